//! A body JSON file (`sublevel fit` output, `UploadBody.body_json`): parse, then validate as a
//! body. Ok or Err, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(file) = serde_json::from_slice::<sublevel::body::BodyFile>(data) {
        let _ = sublevel::Body::from_file(file);
    }
});
