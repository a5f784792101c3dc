//! Arbitrary bytes (lossily converted to text) must parse or fail with an error, never panic.
//! A successful parse must also survive a write and re-read.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use zoo_data::bvh::{ReadOptions, parse, to_string};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    for drop_dummy_root in [false, true] {
        let opts = ReadOptions { drop_dummy_root };
        if let Ok(clip) = parse(&text, Path::new("fuzz.bvh"), &opts) {
            let again = to_string(&clip);
            let back = parse(
                &again,
                Path::new("fuzz-rewritten.bvh"),
                &ReadOptions::default(),
            )
            .expect("a written clip re-reads");
            assert_eq!(back.frames(), clip.frames());
            assert_eq!(back.joints(), clip.joints());
        }
    }
});
