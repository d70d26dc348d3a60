//! The bake decoders (header, chunk, whole file) on arbitrary bytes
//! (`bspvt_tests::fuzz::decode`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bspvt_tests::fuzz::decode(data);
});
