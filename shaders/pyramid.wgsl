// The height-field pyramid pre-pass (src/heightfield/pyramid.rs, decimate): every level
// j > 0 is the level-0 map filtered by a separable tent of one output spacing,
// clamp-to-edge, each level directly from level 0. The host generates the tap lists
// (the same ones the CPU path applies); these two passes apply them, x then y, for all
// levels in one dispatch each (global_invocation_id.z = level - 1).

@group(0) @binding(0) var<storage, read> decimations: array<GpuDecimation>;
// (first tap, tap count) per output sample.
@group(0) @binding(1) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> taps: array<GpuTap>;
@group(0) @binding(3) var<storage, read_write> scratch: array<f32>;
// Level 0 first (uploaded), then each level at its offset.
@group(0) @binding(4) var<storage, read_write> levels: array<f32>;

// Along x: in_rows rows of out_columns values into the scratch buffer.
@compute @workgroup_size(WORKGROUP_SIZE, 1, 1)
fn decimate_x(@builtin(global_invocation_id) id: vec3<u32>) {
    let d = decimations[id.z];
    let column = id.x;
    let row = id.y;
    if column >= d.out_columns || row >= d.in_rows {
        return;
    }
    let range = ranges[d.ranges_x + column];
    var sum = 0.0;
    for (var t = range.x; t < range.x + range.y; t++) {
        sum += taps[t].weight * levels[row * d.in_columns + taps[t].index];
    }
    scratch[d.scratch_offset + row * d.out_columns + column] = sum;
}

// Along y: the level's out_rows rows from the scratch buffer.
@compute @workgroup_size(WORKGROUP_SIZE, 1, 1)
fn decimate_y(@builtin(global_invocation_id) id: vec3<u32>) {
    let d = decimations[id.z];
    let column = id.x;
    let row = id.y;
    if column >= d.out_columns || row >= d.out_rows {
        return;
    }
    let range = ranges[d.ranges_y + row];
    var sum = 0.0;
    for (var t = range.x; t < range.x + range.y; t++) {
        sum += taps[t].weight * scratch[d.scratch_offset + taps[t].index * d.out_columns + column];
    }
    levels[d.level_offset + row * d.out_columns + column] = sum;
}
