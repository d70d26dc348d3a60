//! The service tests' view of the one harness (`bspvt_tests::service`): this package's own
//! binary, `bspvt-server`.

#![allow(dead_code)]

use std::path::Path;

pub use bspvt_tests::service::*;

/// The service binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_bspvt-server");

/// `bspvt-server serve` on `data_dir`, a free loopback port, with extra flags.
pub fn start(data_dir: &Path, extra: &[&str]) -> Server {
    Server::start(BIN, data_dir, "127.0.0.1:0", extra)
}

/// The offline bake (`bspvt-server bake`) of a scene file.
pub fn offline_bake(dir: &Path, scene_json: &str, name: &str) -> Vec<u8> {
    bspvt_tests::service::offline_bake(BIN, dir, scene_json, name)
}
