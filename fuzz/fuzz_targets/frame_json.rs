//! Per-frame JSON: blockers.####.json and camera.####.json readers on the same bytes.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = common::file("frame.json", data);
    let _ = logsh::scene::camera::read_blockers(&path, 1);
    let _ = logsh::scene::Camera::read(&path, 1);
});
