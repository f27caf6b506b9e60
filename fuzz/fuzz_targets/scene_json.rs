//! scene.json: Scene::load must return an error, never panic, on any bytes.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    common::file("scene.json", data);
    let _ = logsh::scene::Scene::load(common::scratch());
});
