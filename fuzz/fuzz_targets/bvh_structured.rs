//! Near-valid BVH: a valid file built from the input's bytes (joint count, channel layouts,
//! values), then mutated at one byte position chosen by the input. Reaches the motion section
//! far more often than random bytes do.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::fmt::Write;
use std::path::Path;
use zoo_data::bvh::{ReadOptions, parse};

const CHANNELS: [&str; 6] = [
    "Xposition",
    "Yposition",
    "Zposition",
    "Xrotation",
    "Yrotation",
    "Zrotation",
];

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let mut it = data.iter().copied().cycle();
    let mut next = || it.next().unwrap_or(0);
    let joints = 1 + (next() % 5) as usize;
    let frames = (next() % 4) as usize;
    let mut s = String::from("HIERARCHY\n");
    let mut columns = 0;
    for j in 0..joints {
        let kw = if j == 0 { "ROOT" } else { "JOINT" };
        let _ = writeln!(s, "{kw} j{j}\n{{\n OFFSET {} 0 -1.5", next() as i8);
        let six = next() % 2 == 0;
        let mut chans: Vec<&str> = if six {
            CHANNELS.to_vec()
        } else {
            CHANNELS[3..].to_vec()
        };
        // shuffle the channel order
        for i in (1..chans.len()).rev() {
            let k = next() as usize % (i + 1);
            chans.swap(i, k);
        }
        columns += chans.len();
        let _ = writeln!(s, " CHANNELS {} {}", chans.len(), chans.join(" "));
        if next() % 3 == 0 {
            s.push_str(" End Site\n {\n OFFSET 0 1 0\n }\n");
        }
    }
    for _ in 0..joints {
        s.push_str("}\n");
    }
    let _ = write!(s, "MOTION\nFrames: {frames}\nFrame Time: 0.0333\n");
    for _ in 0..frames {
        for c in 0..columns {
            let _ = write!(
                s,
                "{}{}",
                if c > 0 { "\t" } else { "" },
                next() as i8 as f64 * 7.25
            );
        }
        s.push_str("\r\n");
    }
    let mut bytes = s.into_bytes();
    let at = (next() as usize * 256 + next() as usize) % bytes.len();
    match next() % 4 {
        0 => {
            bytes.remove(at);
        }
        1 => bytes[at] = next(),
        2 => bytes.insert(at, next()),
        _ => {}
    }
    let text = String::from_utf8_lossy(&bytes);
    for drop_dummy_root in [false, true] {
        let _ = parse(
            &text,
            Path::new("fuzz.bvh"),
            &ReadOptions { drop_dummy_root },
        );
    }
});
