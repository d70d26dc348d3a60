//! A whole `POST /scenes` body: multipart parsing, the form's fields, decompression, the
//! importers and the scene's composition (`bspvt_server::service::fuzz::upload`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    bspvt_server::service::fuzz::upload(data);
});
