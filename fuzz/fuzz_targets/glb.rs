//! The Glb importer on arbitrary bytes (`bspvt_tests::fuzz::import`).
#![no_main]

use bspvt_proto::import::Format;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bspvt_tests::fuzz::import(data, Format::Glb);
});
