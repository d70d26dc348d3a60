//! A scene JSON submitted to the service, with a small mesh and alone
//! (`bspvt_server::service::fuzz::scene_json`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bspvt_server::service::fuzz::scene_json(data);
});
