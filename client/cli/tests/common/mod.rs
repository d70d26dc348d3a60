//! Shared helpers of the streaming tests: the one service harness (`bspvt_tests::service`)
//! started as `bspvt serve` (this package's own binary), and the offline reference.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::sync::atomic::AtomicBool;

use bspvt_client::frame::image::Image;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_client::session::connect::ConnectOptions;
use bspvt_proto::encoding::{Bake, decode_bake};
use bspvt_proto::scene::open_scene;

#[allow(unused_imports, reason = "not every test binary uses every helper")]
pub use bspvt_tests::service::{Server, plate_small};

/// The client's binary: `bspvt serve` runs the same service.
pub const BIN: &str = env!("CARGO_BIN_EXE_bspvt");

/// `bspvt serve` on `data_dir`, listening on `addr` (e.g. `127.0.0.1:0`).
pub fn start(data_dir: &Path, addr: &str, extra: &[&str]) -> Server {
    Server::start(BIN, data_dir, addr, extra)
}

/// How a test client reaches `server`: the scene file submitted there, a private cache.
pub fn connect_args(scene: &Path, server: &Server, tmp: &Path) -> ConnectOptions {
    ConnectOptions {
        source: Some(scene.to_string_lossy().into_owned()),
        mesh: None,
        server: Some(server.base.clone()),
        api_key: None,
        data_dir: tmp.join("client"),
        cache_dir: Some(tmp.join("cache")),
        embedded: None,
    }
}

/// The offline bake of a scene file, in this process (the same engine as `bspvt-server bake`).
pub fn offline_bake(scene: &Path) -> Bake {
    let scene = open_scene(Some(&scene.to_string_lossy()), None).expect("scene");
    let out = bspvt_bake::Baker::new(&scene)
        .bake_all(&|_, _| {}, &AtomicBool::new(false))
        .expect("bake");
    decode_bake(&out.bytes).expect("decode")
}

/// The frame of `scene` lit by `light`, shaded with the offline bake's trees.
pub fn offline_frame(
    scene: &bspvt_proto::Scene,
    bake: &Bake,
    camera: &bspvt_proto::scene::Camera,
    light: &bspvt_client::light::Light,
    mode: Mode,
    size: u32,
) -> Image {
    let r = Renderer::with_camera(scene, camera, size, size);
    r.bspvt(
        std::slice::from_ref(light),
        &Trees::full(&bake.trees, bake.header.codec()),
        mode,
    )
    .0
}

pub fn all_finite(img: &Image) -> bool {
    img.pixels.iter().flatten().all(|c| c.is_finite())
}
