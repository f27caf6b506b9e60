//! Image loading: the G-buffer, height map, environment and transfer-frame readers (EXR,
//! and Radiance HDR for the environment), and the header listing of `logsh info`, on the
//! same bytes.
//! Each must return an error, never panic, and never allocate for a size the header
//! claims before checking it.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;
use logsh::scene::{ChannelNames, EnvironmentMap, GBuffer, HeightMap, Material};
use std::collections::BTreeMap;

fuzz_target!(|data: &[u8]| {
    let path = common::file("image.exr", data);
    let materials = BTreeMap::from([(1, Material::Diffuse { albedo: [0.5; 3] })]);
    let _ = GBuffer::read(&path, &ChannelNames::default(), &materials);
    let _ = HeightMap::read(&path, None, [-1.0, -1.0], [1.0, 1.0]);
    let _ = EnvironmentMap::read(&path);
    let _ = logsh::info::describe(&path);
    let _ = logsh::transfer::TransferFrame::read(&path);
    let hdr = common::file("image.hdr", data);
    let _ = EnvironmentMap::read(&hdr);
});
