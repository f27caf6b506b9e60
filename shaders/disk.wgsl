// Directions over a disk and their visibility (src/shade/sun.rs, DiskDirections): a sun's
// disk, or the core of a sharp glossy lobe (src/shade/glossy.rs). DISK_DIRECTIONS
// directions uniform by solid angle (T_DISK holds the unit-disk pattern, x then y), held
// four to a vec4 so that each occluder updates them in DISK_QUADS steps. Each direction's
// blocked share is that of its patch, from the sine of the signed angle to the nearest
// occluder boundary, the largest over the occluders (sun.rs, module doc). No inverse
// trigonometry decides a share: Vulkan bounds asin and atan only to 4096 ulp, which on
// lavapipe moved a penumbra by a tenth of a patch. The disk's 1 - cos and its patch
// radius come from the host, computed in f64.

struct Disk {
    x: array<vec4<f32>, DISK_QUADS>,
    y: array<vec4<f32>, DISK_QUADS>,
    z: array<vec4<f32>, DISK_QUADS>,
}

// The disk whose half-angle has cosine 1 - `one_minus_cos` about unit `axis`
// (DiskDirections::new, with frame_around's helper axis); the sines are taken from
// 1 - cos, so that a mirror's core, a few thousandths of a radian, keeps its shape in f32.
fn disk_around(axis: vec3<f32>, one_minus_cos: f32) -> Disk {
    var helper = vec3<f32>(1.0, 0.0, 0.0);
    if abs(axis.z) < 0.9 {
        helper = vec3<f32>(0.0, 0.0, 1.0);
    }
    let e1 = normalize(cross(helper, axis));
    let e2 = cross(axis, e1);
    var disk: Disk;
    for (var q = 0u; q < DISK_QUADS; q++) {
        let i = T_DISK + 4u * q;
        let j = i + DISK_DIRECTIONS;
        let px = vec4<f32>(tables[i], tables[i + 1u], tables[i + 2u], tables[i + 3u]);
        let py = vec4<f32>(tables[j], tables[j + 1u], tables[j + 2u], tables[j + 3u]);
        let r2 = px * px + py * py;
        let drop = one_minus_cos * r2;
        let cos_t = 1.0 - drop;
        let sin_t = sqrt(max(drop * (2.0 - drop), vec4<f32>(0.0)));
        // Every point of the pattern is off the centre (radius sqrt((i + 1/2) / K)).
        let r = sqrt(r2);
        let c = px / r;
        let s = py / r;
        disk.x[q] = cos_t * axis.x + sin_t * (c * e1.x + s * e2.x);
        disk.y[q] = cos_t * axis.y + sin_t * (c * e1.y + s * e2.y);
        disk.z[q] = cos_t * axis.z + sin_t * (c * e1.z + s * e2.z);
    }
    return disk;
}

fn covered(sin_x: vec4<f32>, two_patches: f32) -> vec4<f32> {
    return clamp(0.5 + sin_x / two_patches, vec4<f32>(0.0), vec4<f32>(1.0));
}

// Blocked share of each direction of `disk` (about `axis`, with 1 - cos of its half-angle
// `one_minus_cos` and patch radius `patch_radius`) at p with normal n on object `object`:
// the tangent plane and the ground plane when asked, the horizon along the axis's
// azimuth, and every sphere of the blocker tree that reaches the cone, never a cluster
// (DiskDirections::visibility, BlockerTree::visit_cone); only what is nearer than `reach`
// (a point lamp's distance; 3e38 for a sun or a lobe). A sun with a shadow map (at
// `shadow_map` in the tables, its rays drifting `drift` sideways per unit of depth)
// takes the map's columns in place of the spheres.
fn disk_blocked(disk: ptr<function, Disk>, p: vec3<f32>, n: vec3<f32>, object: u32, axis: vec3<f32>, one_minus_cos: f32, patch_radius: f32, reach: f32, tangent: bool, ground: bool, shadow_map: u32, drift: f32) -> array<vec4<f32>, DISK_QUADS> {
    let two_patches = 2.0 * patch_radius;
    var blocked: array<vec4<f32>, DISK_QUADS>;
    if tangent {
        for (var q = 0u; q < DISK_QUADS; q++) {
            blocked[q] = covered(-(n.x * (*disk).x[q] + n.y * (*disk).y[q] + n.z * (*disk).z[q]), two_patches);
        }
    }
    // The ground hides nothing of a lamp above it (sun.rs, ground_counts).
    let lamp_above = reach < 1.0e38 && p.z + axis.z * reach > GROUND_HEIGHT;
    if ground && GROUND && p.z > GROUND_HEIGHT + 1e-4 * (1.0 + abs(GROUND_HEIGHT)) && !lamp_above {
        for (var q = 0u; q < DISK_QUADS; q++) {
            blocked[q] = max(blocked[q], covered(-(*disk).z[q], two_patches));
        }
    }
//#if HEIGHTFIELD
    let horizontal = length(axis.xy);
    if enabled(FEATURE_HEIGHTFIELD) && horizontal > 1e-9 {
        let horizon = horizon_along(p, axis.xy / horizontal, reach * horizontal);
        let sin_h = sin(horizon);
        let cos_h = cos(horizon);
        for (var q = 0u; q < DISK_QUADS; q++) {
            // x = horizon - elevation, in [-pi, pi] (a lamp's horizon may lie below the
            // horizontal): past pi/2 either way it is deep inside or far outside.
            let sin_e = (*disk).z[q];
            let cos_e = sqrt(max(1.0 - sin_e * sin_e, vec4<f32>(0.0)));
            let cos_x = cos_h * cos_e + sin_h * sin_e;
            let beyond = select(vec4<f32>(0.0), vec4<f32>(1.0), vec4<f32>(sin_h) > sin_e);
            let share = select(covered(sin_h * cos_e - cos_h * sin_e, two_patches), beyond, cos_x < vec4<f32>(0.0));
            blocked[q] = max(blocked[q], share);
        }
    }
//#endif
    // A sun's shadow map of the blocker meshes, in place of the spheres.
    if shadow_map != NO_MAP {
        shadow_blocked(disk, &blocked, shadow_map, drift, p, n);
        return blocked;
    }
//#if BLOCKERS
    // The cone's reach for culling, with a margin for acos, atan2 and asin's 4096 ulp:
    // a sphere kept that does not reach the disk blocks nothing.
    let cone_reach = acos(1.0 - one_minus_cos) + patch_radius + 0.01;
    var i = 0u;
    while i < params.node_count {
        let node = blocker_tree[i];
        let d = node.bounds.xyz - p;
        let r = node.bounds.w;
        if behind_tangent_plane(d, r, n) {
            i = node.skip;
            continue;
        }
        let distance = length(d);
        // Outside the cone: the angle to the bounds' centre beyond the cone's half-angle
        // plus the bounds' own angular radius.
        if distance > r && atan2(length(cross(axis, d)), dot(axis, d)) > cone_reach + asin(r / distance) {
            i = node.skip;
            continue;
        }
        if node.leaf != 0u {
            let sphere = node.equivalent;
            let to_sphere = sphere.xyz - p;
            let sphere_distance = length(to_sphere);
            let own = object != 0u && node.object == object;
            let beyond = sphere_distance - sphere.w >= reach;
            if sphere_distance > 0.0 && !beyond && !(own && (own_sphere_holds(p, sphere) || dot(to_sphere, n) <= 0.0)) {
                let a = to_sphere / sphere_distance;
                // The cap's half-angle: asin(r / d), a hemisphere from inside.
                let sin_cap = min(sphere.w / sphere_distance, 1.0);
                let cos_cap = sqrt(max(1.0 - sin_cap * sin_cap, 0.0));
                for (var q = 0u; q < DISK_QUADS; q++) {
                    // x = cap - angle, in [-pi, pi/2]: below -pi/2 it is far outside.
                    let x = (*disk).x[q];
                    let y = (*disk).y[q];
                    let z = (*disk).z[q];
                    let cx = a.y * z - a.z * y;
                    let cy = a.z * x - a.x * z;
                    let cz = a.x * y - a.y * x;
                    let cos_a = a.x * x + a.y * y + a.z * z;
                    let sin_a = sqrt(cx * cx + cy * cy + cz * cz);
                    let cos_x = cos_cap * cos_a + sin_cap * sin_a;
                    let share = select(covered(sin_cap * cos_a - cos_cap * sin_a, two_patches), vec4<f32>(0.0), cos_x < vec4<f32>(0.0));
                    blocked[q] = max(blocked[q], share);
                }
            }
            i = node.skip;
            continue;
        }
        i++;
    }
//#endif
    return blocked;
}

//#if HEIGHTFIELD
// The horizon elevation from p along unit `dir` in the xy plane, over the steps no
// farther than `reach` (pyramid.rs, horizon_along): add_heightfield's march for one
// azimuth.
fn horizon_along(p: vec3<f32>, dir: vec2<f32>, reach: f32) -> f32 {
    var above = 0.0;
    var receiver: array<f32, LEVELS>;
    var ceilings: array<f32, STEP_ARRAY>;
    if !march_start(p, &above, &receiver, &ceilings) {
        return 0.0;
    }
    return horizon(p.x, p.y, above, dir, reach, &receiver, &ceilings);
}
//#endif

// The columns of a sun's shadow map that block each direction of `disk` from p with
// normal n (src/shade/sun_shadow.rs, ShadowMapMarch::blocked, whose module doc gives the
// march): the map's record at `base` in the tables, `drift` the disk's sideways drift per
// unit of depth. A blocked direction's share is 1.
fn shadow_blocked(disk: ptr<function, Disk>, blocked: ptr<function, array<vec4<f32>, DISK_QUADS>>, base: u32, drift: f32, p: vec3<f32>, n: vec3<f32>) {
    let map = load_GpuShadowMap(base);
    let axis = map.axis.xyz;
    let texel = map.axis.w;
    let rel = p - map.origin.xyz;
    let cos_n = max(abs(dot(n, axis)), 1e-6);
    let tan_n = min(sqrt(max(1.0 - cos_n * cos_n, 0.0)) / cos_n, 8.0);
    let bias = texel * (1.0 + 2.0 * tan_n);
    let across = vec2<f32>(dot(rel, map.right.xyz), dot(rel, map.up.xyz));
    let depth = -dot(rel, axis);
    let clear_below = depth - bias;
    let top = map.origin.w;
    if clear_below <= top {
        return;
    }
    let own = shadow_texel(map, across);
    if own.x >= 0 && shadow_meets(map, base, own, depth, depth, bias) {
        for (var q = 0u; q < DISK_QUADS; q++) {
            (*blocked)[q] = vec4<f32>(1.0);
        }
        return;
    }
    let nearby = shadow_shallowest_around(map, base, across, (clear_below - top) * drift);
    if nearby >= clear_below {
        return;
    }
    let reach = clear_below - nearby;
    let start = shadow_coordinates(map, across);
    for (var q = 0u; q < DISK_QUADS; q++) {
        for (var c = 0u; c < 4u; c++) {
            let w = vec3<f32>((*disk).x[q][c], (*disk).y[q][c], (*disk).z[q][c]);
            let along = dot(w, axis);
            if along > 0.5 {
                let velocity = vec2<f32>(dot(w, map.right.xyz), -dot(w, map.up.xyz)) / texel;
                if shadow_ray_meets(map, base, start, velocity, reach / along, depth, along, bias) {
                    (*blocked)[q][c] = 1.0;
                }
            }
        }
    }
}

// `across` in level 0's texels, fractional (ShadowMapMarch::texel_coordinates).
fn shadow_coordinates(map: GpuShadowMap, across: vec2<f32>) -> vec2<f32> {
    return vec2<f32>((across.x / map.right.w + 0.5) * f32(map.columns), (0.5 - across.y / map.up.w) * f32(map.rows));
}

// Whether the ray from `start` (texel coordinates) moving `velocity` texels per unit t, at
// depth `depth - t along`, meets the meshes' interval of a texel it crosses before t =
// `end` (ShadowMapMarch::ray_meets: the texels walked one boundary at a time).
fn shadow_ray_meets(map: GpuShadowMap, base: u32, start: vec2<f32>, velocity: vec2<f32>, end: f32, depth: f32, along: f32, bias: f32) -> bool {
    var cell = floor(start);
    let step = select(vec2<f32>(-1.0), vec2<f32>(1.0), velocity > vec2<f32>(0.0));
    var next = vec2<f32>(shadow_crossing(start.x, velocity.x, cell.x), shadow_crossing(start.y, velocity.y, cell.y));
    var enter = 0.0;
    for (var k = 0u; k < MAP_MAX_STEPS; k++) {
        let exit = min(min(next.x, next.y), end);
        let inside = cell.x >= 0.0 && cell.y >= 0.0 && cell.x < f32(map.columns) && cell.y < f32(map.rows);
        if inside && shadow_meets(map, base, vec2<i32>(cell), depth - enter * along, depth - exit * along, bias) {
            return true;
        }
        if exit >= end {
            return false;
        }
        if next.y < next.x {
            cell.y += step.y;
            next.y = shadow_crossing(start.y, velocity.y, cell.y);
        } else {
            cell.x += step.x;
            next.x = shadow_crossing(start.x, velocity.x, cell.x);
        }
        enter = exit;
    }
    return false;
}

// The t at which a ray from `start` moving `v` per unit t leaves `cell` along one axis.
fn shadow_crossing(start: f32, v: f32, cell: f32) -> f32 {
    if v > 0.0 {
        return (cell + 1.0 - start) / v;
    }
    if v < 0.0 {
        return (cell - start) / v;
    }
    return 3.0e38;
}

// Level 0's texel under `across` (ShadowMapMarch::texel_under), x = -1 off the map.
fn shadow_texel(map: GpuShadowMap, across: vec2<f32>) -> vec2<i32> {
    let at = floor(shadow_coordinates(map, across));
    if at.x < 0.0 || at.y < 0.0 || at.x >= f32(map.columns) || at.y >= f32(map.rows) {
        return vec2<i32>(-1);
    }
    return vec2<i32>(at);
}

// Whether the depths from `deep` up to `shallow` meet the meshes' interval at `texel`,
// both its ends lowered by `bias` (ShadowMapMarch::meets).
fn shadow_meets(map: GpuShadowMap, base: u32, texel: vec2<i32>, deep: f32, shallow: f32, bias: f32) -> bool {
    let at = u32(texel.y) * map.columns + u32(texel.x);
    let level = load_GpuLevel(base + GpuShadowMap_FLOATS);
    return tables[level.offset + at] < deep - bias && shallow < tables[map.far + at] + bias;
}

// The shallowest depth over the texels the square of half-side `half` about `across`
// touches, from the coarsest level whose 2 x 2 texels cover it
// (ShadowMapMarch::shallowest_around); 3e38 where it lies wholly off the map.
fn shadow_shallowest_around(map: GpuShadowMap, base: u32, across: vec2<f32>, half: f32) -> f32 {
    let columns = f32(map.columns);
    let rows = f32(map.rows);
    let low = floor(shadow_coordinates(map, across + vec2<f32>(-half, half)));
    let high = floor(shadow_coordinates(map, across + vec2<f32>(half, -half)));
    let fx0 = low.x;
    let fy0 = low.y;
    let fx1 = high.x;
    let fy1 = high.y;
    if fx1 < 0.0 || fy1 < 0.0 || fx0 >= columns || fy0 >= rows {
        return 3.0e38;
    }
    var x0 = u32(clamp(fx0, 0.0, columns - 1.0));
    var x1 = u32(clamp(fx1, 0.0, columns - 1.0));
    var y0 = u32(clamp(fy0, 0.0, rows - 1.0));
    var y1 = u32(clamp(fy1, 0.0, rows - 1.0));
    var level = 0u;
    while x1 - x0 > 1u || y1 - y0 > 1u {
        x0 /= 2u;
        x1 /= 2u;
        y0 /= 2u;
        y1 /= 2u;
        level++;
    }
    let l = load_GpuLevel(base + GpuShadowMap_FLOATS + GpuLevel_FLOATS * level);
    let a = min(tables[l.offset + y0 * l.columns + x0], tables[l.offset + y0 * l.columns + x1]);
    let b = min(tables[l.offset + y1 * l.columns + x0], tables[l.offset + y1 * l.columns + x1]);
    return min(a, b);
}
