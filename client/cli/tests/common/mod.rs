//! Shared helpers of the streaming tests: the real service (`bspvt serve`, this package's own
//! binary) on loopback with a temporary data folder, scene files, and the offline reference.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::time::Duration;

use bspvt_client::frame::image::Image;
use bspvt_client::render::renderer::{Mode, Renderer, Trees};
use bspvt_client::session::connect::ConnectOptions;
use bspvt_proto::encoding::{Bake, decode_bake};
use bspvt_proto::scene::open_scene;

pub const BIN: &str = env!("CARGO_BIN_EXE_bspvt");

/// A running service process.
pub struct Server {
    pub child: Child,
    /// `http://127.0.0.1:PORT`
    pub base: String,
    pub data_dir: PathBuf,
}

impl Server {
    /// Starts `bspvt serve` on `data_dir` (`addr`: e.g. `127.0.0.1:0`); waits for its address.
    pub fn start(data_dir: &Path, addr: &str, extra: &[&str]) -> Server {
        let mut child = Command::new(BIN)
            .arg("serve")
            .arg("--data-dir")
            .arg(data_dir)
            .args(["--addr", addr])
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start bspvt serve");
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        let line = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the service did not start");
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
            .to_string();
        Server {
            child,
            base,
            data_dir: data_dir.to_path_buf(),
        }
    }

    /// `127.0.0.1:PORT`
    pub fn addr(&self) -> &str {
        self.base.trim_start_matches("http://")
    }

    /// SIGKILL, then reap.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill();
    }
}

/// The small built-in scene with explicit bake settings, written to `dir/NAME.json`.
pub fn plate_small(dir: &Path, name: &str, face_res: u32, chunk_vertices: u32) -> PathBuf {
    let json = format!(
        r#"{{"meshes": [{{"path": "builtin:plate-small"}}],
  "materials": [{{"name": "floor", "roughness": 0.35, "albedo": [0.55, 0.55, 0.52]}},
                {{"name": "sphere", "roughness": 0.15, "albedo": [0.6, 0.15, 0.1]}},
                {{"name": "slab", "roughness": 0.5, "albedo": [0.2, 0.35, 0.6]}}],
  "lights": [{{"vertices": [[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]],
              "radiance": [12, 11, 10],
              "region": {{"min": [-2.5, 2, -2.5], "max": [2.5, 4, 2.5]}}}}],
  "camera": {{"position": [3.2, 3.0, 4.2], "target": [0.0, 0.5, 0.0]}},
  "bake": {{"face_res": {face_res}, "chunk_vertices": {chunk_vertices}}}}}"#
    );
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, json).expect("write scene");
    path
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
    r.bspvt(light, &Trees::full(&bake.trees, bake.header.codec()), mode)
        .0
}

pub fn all_finite(img: &Image) -> bool {
    img.pixels.iter().flatten().all(|c| c.is_finite())
}
