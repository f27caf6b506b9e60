// The shading pass: one invocation per shading point of a tile (paper 000, Sections 4-5
// and Eq. 9; src/shade/kernel.rs is the CPU executor of the same steps). Sums the log-SH
// visibility of the tangent plane, the height field and every sphere blocker, adds each
// BRDF lobe in log-SH, exponentiates, and dots with the light's SH vector.
//
// The host composes this file with the modules the scene needs and strips the blocks
// between `//#if FEATURE` and `//#endif` whose feature the scene lacks, so a scene pays
// only for what it contains; the prelude it generates declares ORDER, COUNT, the table
// offsets T_* and the feature constants.

@group(0) @binding(0) var<uniform> params: ShadeParams;
@group(0) @binding(1) var<storage, read> tables: array<f32>;
@group(0) @binding(2) var<storage, read> points: array<GpuPoint>;
@group(0) @binding(3) var<storage, read_write> shaded: array<GpuShaded>;
@group(0) @binding(4) var<storage, read> materials: array<GpuMaterial>;
//#if BLOCKERS
@group(0) @binding(5) var<storage, read> blocker_tree: array<GpuBlockerNode>;
//#endif
//#if HEIGHTFIELD
@group(0) @binding(6) var<storage, read> levels: array<f32>;
@group(0) @binding(7) var<storage, read> level_table: array<GpuLevel>;
@group(0) @binding(8) var<storage, read> steps: array<GpuStep>;
//#endif
//#if GRID
// The visibility grid's block records (src/gpu/program.rs, VisibilityBlocks): written by
// the pre-pass `grid_visibility`, read by `shade`.
@group(0) @binding(9) var<storage, read_write> grid: array<f32>;
//#endif

// Whether the frame has a feature: decided when the program is generated, except in the
// generic program that measures what specialisation saves.
fn enabled(feature: u32) -> bool {
    return !GENERIC || (params.feature_bits & feature) != 0u;
}

// exp*(f) . light per colour channel (kernel.rs, Exponentiator::exp and lit). SH-space
// methods hand pixels with |f^| beyond their range to the quadrature, as on the CPU. `v`
// is the log visibility within f, which the quadrature floors (exp_quad.wgsl).
fn exp_dot_light(f: ptr<function, array<f32, COUNT_CAP>>, v: ptr<function, array<f32, COUNT_CAP>>, ceiling: f32) -> vec3<f32> {
//#if EXP_QUAD
    return max(quad_exp_dot_light(f, v, ceiling), vec3<f32>(0.0));
//#else
    // Blended into quad over the band below the method's range (kernel.rs,
    // quadrature_weight), so the hand-over leaves no seam.
    let magnitude = non_dc_magnitude(f);
    var weight = 1.0;
    if magnitude <= SH_SPACE_MAX_MAGNITUDE {
        weight = clamp((magnitude - (SH_SPACE_MAX_MAGNITUDE - SH_SPACE_BLEND)) / SH_SPACE_BLEND, 0.0, 1.0);
    }
    if weight >= 1.0 {
        return max(quad_exp_dot_light(f, v, ceiling), vec3<f32>(0.0));
    }
    var hat = *f;
    hat[0] = 0.0;
    var e: array<f32, COUNT_CAP>;
//#if EXP_OL
    ol_exp_non_dc(&hat, magnitude, &e);
    let dc_factor = exp((*f)[0] * Y0);
    for (var i = 0u; i < COUNT; i++) {
        e[i] *= dc_factor;
    }
//#endif
//#if EXP_HYB
    // HYB (paper 000, Section 3.3): scale f^ below the threshold, OL, then square back up;
    // the DC factor is split over the squarings so it never overflows (exp.rs, exp_hyb_with).
    var squarings = 0u;
    var scale = 1.0;
    while magnitude * scale > params.hyb_threshold && squarings < HYB_MAX_SQUARINGS {
        scale *= 0.5;
        squarings++;
    }
    for (var i = 0u; i < COUNT; i++) {
        hat[i] *= scale;
    }
    ol_exp_non_dc(&hat, magnitude * scale, &e);
    let dc_share = exp((*f)[0] * Y0 * scale);
    for (var i = 0u; i < COUNT; i++) {
        e[i] *= dc_share;
    }
    var squared: array<f32, COUNT_CAP>;
    for (var s = 0u; s < squarings; s++) {
        sh_product(&e, &e, &squared);
        e = squared;
    }
//#endif
//#if EXP_SERIES
    // DC isolation and the Taylor series of exp(f^) by repeated products (exp.rs,
    // exp_series), stopped when a term no longer changes the sum in f32.
    let dc_factor = exp((*f)[0] * Y0);
    var term = hat;
    var sum = hat;
    sum[0] += ONE_DC;
    var next: array<f32, COUNT_CAP>;
    let tolerance = SERIES_TOLERANCE;
    for (var k = 2u; k <= SERIES_MAX_TERMS; k++) {
        sh_product(&term, &hat, &next);
        let inv_k = 1.0 / f32(k);
        var term_norm = 0.0;
        var sum_norm = 0.0;
        for (var i = 0u; i < COUNT; i++) {
            term[i] = next[i] * inv_k;
            sum[i] += term[i];
            term_norm += term[i] * term[i];
            sum_norm += sum[i] * sum[i];
        }
        if term_norm <= tolerance * tolerance * sum_norm {
            break;
        }
    }
    for (var i = 0u; i < COUNT; i++) {
        e[i] = dc_factor * sum[i];
    }
//#endif
    var lit = dot_light(&e);
    if weight > 0.0 {
        lit = mix(lit, quad_exp_dot_light(f, v, ceiling), weight);
    }
    // Clamped at 0: ringing of a band-limited product can dip below it (kernel.rs, lit).
    return max(lit, vec3<f32>(0.0));
//#endif
}

// Log visibility at p with unit normal n (kernel.rs, add_visibility): the tangent plane
// clamped once (a hemisphere cap around -n, or folded into the height field's horizons
// for an upward-facing receiver), the height field's wedges, the caps of the blocker
// tree's spheres and clusters the receiver sees. Where `from_grid`, the horizon
// elevations and the caps are the visibility grid's (`grid_at`) and nothing is marched
// or walked; the height field's log vector is the grid's `field` where `field_weight` is
// 1, blended with the point's own from the grid's horizons where it is between 0 and 1.
// The caps' sum goes to `caps` too, which the visibility passes read.
fn visibility(p: vec3<f32>, n: vec3<f32>, object: u32, from_grid: bool, horizons: ptr<function, array<f32, DIRECTIONS>>, caps: ptr<function, array<f32, COUNT_CAP>>, field: ptr<function, array<f32, COUNT_CAP>>, field_weight: f32) -> array<f32, COUNT_CAP> {
    var acc: array<f32, COUNT_CAP>;
    var fold_tangent = false;
//#if HEIGHTFIELD
    fold_tangent = TANGENT_OCCLUSION && n.z > 0.0 && enabled(FEATURE_HEIGHTFIELD);
//#endif
    if TANGENT_OCCLUSION && !fold_tangent {
        add_tangent(n, &acc);
    }
    add_ground(p, &acc);
//#if HEIGHTFIELD
    if enabled(FEATURE_HEIGHTFIELD) {
        if from_grid && field_weight >= 1.0 {
            for (var i = 0u; i < COUNT; i++) {
                acc[i] += (*field)[i];
            }
        } else if from_grid && field_weight > 0.0 {
            var own: array<f32, COUNT_CAP>;
            add_horizons(p, n, fold_tangent, from_grid, horizons, &own);
            for (var i = 0u; i < COUNT; i++) {
                acc[i] += field_weight * (*field)[i] + (1.0 - field_weight) * own[i];
            }
        } else {
            add_horizons(p, n, fold_tangent, from_grid, horizons, &acc);
        }
    }
//#endif
//#if BLOCKERS
    if !(from_grid && GRID_CAPS > 0u) {
        visit_blockers(p, n, object, caps);
    }
    for (var i = 0u; i < COUNT; i++) {
        acc[i] += (*caps)[i];
    }
//#endif
    return acc;
}

//#if HEIGHTFIELD
// The height field's log visibility at p: from the grid's horizon elevations where
// `from_grid`, else marched.
fn add_horizons(p: vec3<f32>, n: vec3<f32>, fold_tangent: bool, from_grid: bool, horizons: ptr<function, array<f32, DIRECTIONS>>, acc: ptr<function, array<f32, COUNT_CAP>>) {
//#if GRID
    if from_grid && GRID_HORIZONS > 0u {
        add_given_horizons(horizons, n, fold_tangent, params.log_epsilon, acc);
        return;
    }
//#endif
    add_heightfield(p, n, fold_tangent, params.log_epsilon, acc);
}
//#endif

//#if GRID
// The visibility grid's pre-pass (src/shade/visibility_grid.rs, VisibilityGrid::new):
// the tangents of the horizons' elevations, the caps' log vector and the height field's
// log vector (the block's tangent plane folded in) at each block's point, into its
// record.
@compute @workgroup_size(WORKGROUP_SIZE)
fn grid_visibility(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.grid_columns * params.grid_rows {
        return;
    }
    let record = id.x * GRID_STRIDE;
    if grid[record + 7u] == 0.0 {
        return;
    }
    let p = vec3<f32>(grid[record], grid[record + 1u], grid[record + 2u]);
//#if HEIGHTFIELD
    if GRID_HORIZONS > 0u {
        store_horizon_tangents(p, record + GRID_HEADER);
        let n = vec3<f32>(grid[record + 4u], grid[record + 5u], grid[record + 6u]);
        var sigmas: array<f32, DIRECTIONS>;
        for (var k = 0u; k < GRID_HORIZONS; k++) {
            sigmas[k] = atan(grid[record + GRID_HEADER + k]);
        }
        let fold_tangent = TANGENT_OCCLUSION && n.z > 0.0 && enabled(FEATURE_HEIGHTFIELD);
        var field: array<f32, COUNT_CAP>;
        add_given_horizons(&sigmas, n, fold_tangent, params.log_epsilon, &field);
        for (var i = 0u; i < GRID_FIELD; i++) {
            grid[record + GRID_HEADER + GRID_HORIZONS + GRID_CAPS + i] = field[i];
        }
    }
//#endif
//#if BLOCKERS
    if GRID_CAPS > 0u {
        let n = vec3<f32>(grid[record + 4u], grid[record + 5u], grid[record + 6u]);
        var caps: array<f32, COUNT_CAP>;
        visit_blockers(p, n, bitcast<u32>(grid[record + 3u]), &caps);
        for (var i = 0u; i < GRID_CAPS; i++) {
            grid[record + GRID_HEADER + GRID_HORIZONS + i] = caps[i];
        }
    }
//#endif
}

// How alike the block's point q (normal m) is to the pixel's p (normal n) for their
// visibility (visibility_grid.rs, likeness), the objects already the same: 0 to 1.
fn likeness(p: vec3<f32>, n: vec3<f32>, q: vec3<f32>, m: vec3<f32>) -> f32 {
    let normals = pow(max(dot(n, m), 0.0), GRID_NORMAL_POWER);
    let d = q - p;
    let distance = length(d);
    var off_plane = 0.0;
    if distance > 0.0 {
        off_plane = abs(dot(n, d)) / distance;
    }
    let x = off_plane / GRID_PLANE_WIDTH;
    return normals * exp(-x * x);
}

// The horizon elevations and caps of point `point` (at p, normal n, on `object`),
// interpolated from the four blocks around its pixel, weighted bilinearly and by
// likeness (visibility_grid.rs, VisibilityGrid::at; horizons averaged as tangents), and
// the height field's log vector into `field`, with how much the point takes it rather
// than turn its own horizons (`field_weight`, VisibilityGrid::at), the horizons only
// where it turns its own in part or `wants_horizons`; false where the grid does not serve
// the point or no block is like it, which is then computed alone.
fn grid_at(point: u32, p: vec3<f32>, n: vec3<f32>, object: u32, served: bool, wants_horizons: bool, horizons: ptr<function, array<f32, DIRECTIONS>>, caps: ptr<function, array<f32, COUNT_CAP>>, field: ptr<function, array<f32, COUNT_CAP>>, field_weight: ptr<function, f32>) -> bool {
    if !served {
        return false;
    }
    let pixel = params.tile_start + point;
    let size = f32(GRID_SIZE);
    let half = f32(GRID_SIZE / 2u);
    let u = (f32(pixel % params.image_width) - half) / size;
    let v = (f32(pixel / params.image_width) - half) / size;
    let b0 = floor(u);
    let c0 = floor(v);
    let tu = u - b0;
    let tv = v - c0;
    var total = 0.0;
    var tangents: array<f32, DIRECTIONS>;
    var sum: array<f32, COUNT_CAP>;
    var field_sum: array<f32, COUNT_CAP>;
    // The least n . m of the blocks, -1 where one folds its tangent plane where the point
    // does not (an upward normal folds).
    var least_cosine = 1.0;
    for (var corner = 0u; corner < 4u; corner++) {
        let db = f32(corner / 2u);
        let dc = f32(corner % 2u);
        let bilinear = mix(1.0 - tu, tu, db) * mix(1.0 - tv, tv, dc);
        let b = b0 + db;
        let c = c0 + dc;
        if bilinear <= 0.0 || b < 0.0 || c < 0.0 || b >= f32(params.grid_columns) || c >= f32(params.grid_rows) {
            continue;
        }
        let record = (u32(c) * params.grid_columns + u32(b)) * GRID_STRIDE;
        if grid[record + 7u] == 0.0 || bitcast<u32>(grid[record + 3u]) != object {
            continue;
        }
        let q = vec3<f32>(grid[record], grid[record + 1u], grid[record + 2u]);
        let m = vec3<f32>(grid[record + 4u], grid[record + 5u], grid[record + 6u]);
        let weight = bilinear * likeness(p, n, q, m);
        if weight <= 0.0 {
            continue;
        }
        total += weight;
        for (var k = 0u; k < GRID_HORIZONS; k++) {
            tangents[k] += weight * grid[record + GRID_HEADER + k];
        }
        for (var i = 0u; i < GRID_CAPS; i++) {
            sum[i] += weight * grid[record + GRID_HEADER + GRID_HORIZONS + i];
        }
        for (var i = 0u; i < GRID_FIELD; i++) {
            field_sum[i] += weight * grid[record + GRID_HEADER + GRID_HORIZONS + GRID_CAPS + i];
        }
        var cosine = -1.0;
        if (m.z > 0.0) == (n.z > 0.0) {
            cosine = dot(n, m);
        }
        least_cosine = min(least_cosine, cosine);
    }
    if total < GRID_MIN_WEIGHT {
        return false;
    }
    if GRID_FIELD > 0u {
        *field_weight = clamp((least_cosine - GRID_FIELD_FAR) / (GRID_FIELD_NEAR - GRID_FIELD_FAR), 0.0, 1.0);
    }
    // The horizons only where the point turns its own slices or reads them otherwise.
    if *field_weight < 1.0 || wants_horizons {
        for (var k = 0u; k < GRID_HORIZONS; k++) {
            (*horizons)[k] = atan(tangents[k] / total);
        }
    }
    for (var i = 0u; i < GRID_CAPS; i++) {
        (*caps)[i] = sum[i] / total;
    }
    for (var i = 0u; i < GRID_FIELD; i++) {
        (*field)[i] = field_sum[i] / total;
    }
    return true;
}
//#endif

// The ground plane (kernel.rs, add_visibility): the hemisphere below the horizontal for a
// receiver above it (kernel.rs, above_ground).
fn add_ground(p: vec3<f32>, acc: ptr<function, array<f32, COUNT_CAP>>) {
    if GROUND && p.z > GROUND_HEIGHT + 1e-4 * (1.0 + abs(GROUND_HEIGHT)) {
        add_tangent(vec3<f32>(0.0, 0.0, 1.0), acc);
    }
}

// The hemisphere behind the tangent plane (kernel.rs, the unfolded tangent term).
fn add_tangent(n: vec3<f32>, acc: ptr<function, array<f32, COUNT_CAP>>) {
    var tangent = load_zonal(T_TANGENT);
    add_rotated_zonal(&tangent, 1.0, -n, acc);
}

// lum(lit) / lum(unoccluded), or 1 where the unoccluded receiver gets no light
// (src/shade/kernel/pixel_passes.rs, ratio).
fn luminance_ratio(lit: vec3<f32>, unoccluded: vec3<f32>) -> f32 {
    let below = dot(LUMINANCE, unoccluded);
    if below > 1e-12 {
        return dot(LUMINANCE, lit) / below;
    }
    return 1.0;
}

// exp*(visibility + lobe rotated to axis) . light, for the lobe table at `lobe` (ORDER
// log-ZH values, then the log of the lobe's peak).
fn lit(visibility: ptr<function, array<f32, COUNT_CAP>>, lobe: u32, axis: vec3<f32>) -> vec3<f32> {
    var f = *visibility;
    var zonal = load_zonal(lobe);
    add_rotated_zonal(&zonal, 1.0, axis, &f);
    return exp_dot_light(&f, visibility, tables[lobe + ORDER]);
}

// A Phong material's glossy lobe, at `material.sharp_tables` (program.rs,
// material_slots): its head (GpuLobeHead: LOBE_GGX, LOBE_PHONG, or LOBE_SH for the lobe
// in log-SH, and its width, core and cone share); then, for a prefiltered lobe, the
// cone's weights, the albedo table and the open lobe's ZH.
fn lobe_kind(material: GpuMaterial) -> u32 {
    return load_GpuLobeHead(material.sharp_tables).kind;
}

// The Phong lobe's value at cos theta = z from its axis, widened by a patch of angular
// radius `patch_radius` (glossy.rs, SharpLobe::widened and SharpLobe::value; the log-SH
// lobe is the same Phong lobe; a GGX lobe reflects sharp lights through widened_ggx_lit).
fn widened_phong_value(material: GpuMaterial, patch_radius: f32, z: vec4<f32>) -> vec4<f32> {
    let width = load_GpuLobeHead(material.sharp_tables).width;
    let pi = 3.141592653589793;
    let blur = 0.25 * patch_radius * patch_radius;
    let a2 = 0.5 / (width + 0.5) + blur;
    let exponent = clamp(0.5 / a2 - 0.5, 1.1754944e-38, width);
    return select(vec4<f32>(0.0), (exponent + 1.0) / (2.0 * pi) * pow(max(z, vec4<f32>(1e-30)), vec4<f32>(exponent)), z > vec4<f32>(0.0));
}

// The Fresnel term of reflectance f0 at v . h = c (glossy.rs, Fresnel): the dielectric's
// Fresnel equations up to DIELECTRIC_F0, Schlick's approximation from METAL_F0, mixed
// between.
fn fresnel_at(f0: f32, c: vec4<f32>) -> vec4<f32> {
    let m = 1.0 - c;
    let m2 = m * m;
    let schlick = f0 + (1.0 - f0) * (m2 * m2 * m);
    let metal = clamp((f0 - DIELECTRIC_F0) / (METAL_F0 - DIELECTRIC_F0), 0.0, 1.0);
    if metal >= 1.0 {
        return schlick;
    }
    let root = min(sqrt(max(f0, 0.0)), sqrt(METAL_F0));
    let eta = (1.0 + root) / (1.0 - root);
    let g = sqrt(eta * eta - 1.0 + c * c);
    let a = (g - c) / max(g + c, vec4<f32>(1e-12));
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    let dielectric = select(vec4<f32>(0.0), 0.5 * a * a * (1.0 + b * b), g + c > vec4<f32>(1e-12));
    return dielectric + metal * (schlick - dielectric);
}

// GGX's BRDF times the cosine and the Fresnel term for n . v = n_v, n . w = n_w and
// v . w = v_w, widened by a patch of angular radius `patch_radius` (glossy.rs, ggx_lit
// and SharpLobe::widened).
fn widened_ggx_lit(material: GpuMaterial, patch_radius: f32, n_v: f32, n_w: vec4<f32>, v_w: vec4<f32>) -> vec4<f32> {
    let head = load_GpuLobeHead(material.sharp_tables);
    let a2 = head.width * head.width + 0.25 * patch_radius * patch_radius;
    let mu = clamp(n_v, 1e-4, 1.0);
    let half_length_squared = 2.0 + 2.0 * v_w;
    let half_length = sqrt(max(half_length_squared, vec4<f32>(1e-12)));
    let n_h = min((mu + n_w) / half_length, vec4<f32>(1.0));
    let fresnel = fresnel_at(head.lamp_fresnel, clamp(0.5 * half_length, vec4<f32>(0.0), vec4<f32>(1.0)));
    let d = n_h * n_h * (a2 - 1.0) + 1.0;
    let distribution = a2 / (3.141592653589793 * d * d);
    let lambda_v = 0.5 * (sqrt(1.0 + a2 * (1.0 - mu * mu) / max(mu * mu, 1e-12)) - 1.0);
    let n_w2 = max(n_w * n_w, vec4<f32>(1e-12));
    let lambda_w = 0.5 * (sqrt(1.0 + a2 * (1.0 - n_w2) / n_w2) - 1.0);
    let value = fresnel * distribution / (1.0 + lambda_v + lambda_w) / (4.0 * mu);
    return select(vec4<f32>(0.0), value, n_w > vec4<f32>(0.0) & half_length_squared > vec4<f32>(1e-12));
}

// E(n) / pi, the open receiver's diffuse light in full (kernel.rs, OpenIrradiance): the
// order-8 basis at n, as eval_basis makes it, dotted with the weighted light.
fn irradiance_at(d: vec3<f32>) -> vec3<f32> {
    let count = IRRADIANCE_ORDER * IRRADIANCE_ORDER;
    var sum = vec3<f32>(0.0);
    var cm = 1.0;
    var sm = 0.0;
    for (var m = 0u; m < IRRADIANCE_ORDER; m++) {
        var q_prev = 0.0;
        var q = tables[T_IRRADIANCE_FACTORIAL + m];
        for (var l = m; l < IRRADIANCE_ORDER; l++) {
            if l == m + 1u {
                q_prev = q;
                q = d.z * f32(2u * m + 1u) * q_prev;
            } else if l > m + 1u {
                let next = (f32(2u * l - 1u) * d.z * q - f32(l + m - 1u) * q_prev) / f32(l - m);
                q_prev = q;
                q = next;
            }
            let centre = l * (l + 1u);
            let k = tables[T_IRRADIANCE_NORMALISATION + centre + m] * q;
            if m == 0u {
                sum += k * irradiance_light(centre, count);
            } else {
                sum += k * (cm * irradiance_light(centre + m, count) + sm * irradiance_light(centre - m, count));
            }
        }
        let c = cm * d.x - sm * d.y;
        sm = cm * d.y + sm * d.x;
        cm = c;
    }
    return sum;
}

fn irradiance_light(i: u32, count: u32) -> vec3<f32> {
    return vec3<f32>(tables[T_IRRADIANCE + i], tables[T_IRRADIANCE + count + i], tables[T_IRRADIANCE + 2u * count + i]);
}

// The environment's diffuse light at normal n from log-SH's lit = exp*(V + D) . L (lit.rs,
// open_corrected): E(n) / pi times lit / exp*(T + D) . L per channel in [0, 1].
fn open_corrected(lit: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    if !IRRADIANCE {
        return lit;
    }
    var open: array<f32, COUNT_CAP>;
    var zonal = load_zonal(T_DIFFUSE_OPEN);
    add_rotated_zonal(&zonal, 1.0, n, &open);
    let unoccluded = dot_light(&open);
    let full = max(irradiance_at(n), vec3<f32>(0.0));
    let share = clamp(lit / max(unoccluded, vec3<f32>(1e-30)), vec3<f32>(0.0), vec3<f32>(1.0));
    return select(lit, full * share, unoccluded > vec3<f32>(OPEN_LIGHT_FLOOR));
}

//#if BLOCKERS
// The light's detail beyond order n that the caps seen from p hide (kernel.rs,
// hidden_detail): visit_blockers' walk, each cap's share times its detail.
fn hidden_detail(p: vec3<f32>, n: vec3<f32>, object: u32) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    var i = 0u;
    while i < params.node_count {
        let node = blocker_tree[i];
        let d = node.bounds.xyz - p;
        let r = node.bounds.w;
        if behind_tangent_plane(d, r, n) {
            i = node.skip;
            continue;
        }
        if node.leaf != 0u {
            if !(object != 0u && node.object == object && own_sphere_holds(p, node.equivalent)) {
                sum += node.share * cap_detail(p, n, node.equivalent);
            }
            i = node.skip;
            continue;
        }
        let distance = length(d);
        if distance > r && r <= params.cluster_ratio * distance {
            if node.equivalent.w >= NEGLIGIBLE_RATIO * length(node.equivalent.xyz - p) {
                sum += node.share * cap_detail(p, n, node.equivalent);
            }
            i = node.skip;
            continue;
        }
        i++;
    }
    return sum;
}

// n . M(d, alpha) of the cap `sphere` casts on p (cap_detail.rs, CapDetail::at), faded
// where the tangent plane cuts it (CapDetail::cap_seen): the table's moments read
// trilinearly in direction and radius; 0 for a sphere behind the tangent plane or a cap
// below CAP_DETAIL_MIN_RATIO.
fn cap_detail(p: vec3<f32>, n: vec3<f32>, sphere: vec4<f32>) -> vec3<f32> {
    let d = sphere.xyz - p;
    let distance = length(d);
    if !(distance > 0.0) {
        return vec3<f32>(0.0);
    }
    let direction = d / distance;
    if dot(direction, n) <= 0.0 {
        return vec3<f32>(0.0);
    }
    let ratio = min(sphere.w / distance, 1.0);
    if ratio < CAP_DETAIL_MIN_RATIO {
        return vec3<f32>(0.0);
    }
    let alpha = asin(ratio);
    let cut = min(dot(n, direction) / ratio, 1.0);
    let theta = atan2(length(direction.xy), direction.z);
    let phi = atan2(direction.y, direction.x);
    let columns = f32(CAP_DETAIL_COLUMNS);
    let y = clamp(theta / 3.141592653589793 * f32(CAP_DETAIL_ROWS) - 0.5, 0.0, f32(CAP_DETAIL_ROWS - 1u));
    var x = phi / 6.283185307179586 * columns - 0.5;
    x = x - floor(x / columns) * columns;
    let r = clamp(alpha / CAP_DETAIL_MAX_RADIUS * f32(CAP_DETAIL_RADII - 1u), 0.0, f32(CAP_DETAIL_RADII - 1u));
    let y0 = u32(y);
    let x0 = min(u32(x), CAP_DETAIL_COLUMNS - 1u);
    let r0 = u32(r);
    let f = vec3<f32>(x - f32(x0), y - f32(y0), r - f32(r0));
    let x1 = (x0 + 1u) % CAP_DETAIL_COLUMNS;
    let y1 = min(y0 + 1u, CAP_DETAIL_ROWS - 1u);
    let r1 = min(r0 + 1u, CAP_DETAIL_RADII - 1u);
    var moment: array<f32, 9>;
    for (var corner = 0u; corner < 8u; corner++) {
        let cx = corner & 1u;
        let cy = (corner >> 1u) & 1u;
        let cr = corner >> 2u;
        let column = select(x0, x1, cx == 1u);
        let row = select(y0, y1, cy == 1u);
        let radius = select(r0, r1, cr == 1u);
        let weight = select(1.0 - f.x, f.x, cx == 1u) * select(1.0 - f.y, f.y, cy == 1u) * select(1.0 - f.z, f.z, cr == 1u);
        let at = T_CAP_DETAIL + ((radius * CAP_DETAIL_ROWS + row) * CAP_DETAIL_COLUMNS + column) * 9u;
        for (var k = 0u; k < 9u; k++) {
            moment[k] += weight * tables[at + k];
        }
    }
    return cut * vec3<f32>(
        dot(n, vec3<f32>(moment[0], moment[1], moment[2])),
        dot(n, vec3<f32>(moment[3], moment[4], moment[5])),
        dot(n, vec3<f32>(moment[6], moment[7], moment[8])),
    );
}
//#endif

// The lobe's albedo at n . v = mu, linearly (glossy.rs, albedo_lookup).
fn albedo_lookup(offset: u32, mu: f32) -> f32 {
    let x = clamp(mu, 0.0, 1.0) * f32(ALBEDO_ENTRIES - 1u);
    let i = min(u32(floor(x)), ALBEDO_ENTRIES - 2u);
    return mix(tables[offset + i], tables[offset + i + 1u], x - f32(i));
}

//#if PREFILTERED
// The glossy term read from a prefiltered environment (src/shade/glossy.rs; kernel.rs,
// prefiltered_glossy): A(n . v) P(R) O, with n . v = n . R, O the cone test of the lobe's
// core, the log-SH ratio (from `occlusion`), or a blend.
fn prefiltered_glossy(occlusion: ptr<function, array<f32, COUNT_CAP>>, material: GpuMaterial, p: vec3<f32>, n: vec3<f32>, object: u32, r: vec3<f32>) -> vec3<f32> {
    let head = load_GpuLobeHead(material.sharp_tables);
    let core = head.core_one_minus_cos;
    let core_patch = head.core_patch;
    let share = head.cone_share;
    let weights = material.sharp_tables + GpuLobeHead_FLOATS;
    let albedo = weights + DISK_DIRECTIONS;
    let open_lobe = albedo + 2u * ALBEDO_ENTRIES;
    var by_cone = 0.0;
    if share > 0.0 {
        var disk = disk_around(r, core);
        let blocked = disk_blocked(&disk, p, n, object, r, core, core_patch, 3.0e38, false, false, NO_MAP, 0.0);
        for (var q = 0u; q < DISK_QUADS; q++) {
            let w = vec4<f32>(tables[weights + 4u * q], tables[weights + 4u * q + 1u], tables[weights + 4u * q + 2u], tables[weights + 4u * q + 3u]);
            by_cone += dot(w, 1.0 - blocked[q]);
        }
    }
    var by_sh = 0.0;
    if share < 1.0 {
        // lum(exp*(V + lobe) . L) / lum(exp*(lobe) . L), V without the tangent and ground planes.
        let shadowed = lit(occlusion, material.phong_lobe, r);
        var open: array<f32, COUNT_CAP>;
        var zonal = load_zonal(open_lobe);
        add_rotated_zonal(&zonal, 1.0, r, &open);
        let unshadowed = max(dot_light(&open), vec3<f32>(0.0));
        by_sh = 1.0;
        let below = dot(LUMINANCE, unshadowed);
        if below > 1e-12 {
            by_sh = clamp(dot(LUMINANCE, shadowed) / below, 0.0, 1.0);
        }
    }
    let occluded = share * by_cone + (1.0 - share) * by_sh;
    // glossy.rs, below_tangent_divisor: P(R) as the mean over the lobe above the tangent
    // plane, where the map's lower hemisphere is black.
    var divisor = 1.0;
    if SKY_ONLY {
        let above = max(albedo_lookup(open_lobe + ORDER, dot(n, r)), 0.25);
        divisor = 1.0 - clamp(n.z, 0.0, 1.0) * (1.0 - above);
    }
    let weight = albedo_lookup(albedo, dot(n, r)) * occluded / divisor;
    return prefiltered_lookup(material.sharp_map, r) * weight;
}

// atan2(y, x) to f32 precision. A prefiltered map's texels vary by a fifth of their value
// from one to the next near a bright window's edge, and lavapipe's atan2 and acos,
// bounded by Vulkan only to 4096 ulp, moved a mirror's reflection by 0.3 %: reduced to
// |u| <= tan(pi / 8) and summed to u^15, the series is within 2e-8.
fn precise_atan2(y: f32, x: f32) -> f32 {
    let ax = abs(x);
    let ay = abs(y);
    let largest = max(ax, ay);
    if largest == 0.0 {
        return 0.0;
    }
    let t = min(ax, ay) / largest;
    var u = t;
    var offset = 0.0;
    if t > 0.41421356 {
        u = (t - 1.0) / (t + 1.0);
        offset = 0.7853981633974483;
    }
    let u2 = u * u;
    var series = 1.0 / 15.0;
    series = 1.0 / 13.0 - u2 * series;
    series = 1.0 / 11.0 - u2 * series;
    series = 1.0 / 9.0 - u2 * series;
    series = 1.0 / 7.0 - u2 * series;
    series = 1.0 / 5.0 - u2 * series;
    series = 1.0 / 3.0 - u2 * series;
    series = 1.0 - u2 * series;
    var a = offset + u * series;
    if ay > ax {
        a = 1.5707963267948966 - a;
    }
    if x < 0.0 {
        a = 3.141592653589793 - a;
    }
    if y < 0.0 {
        a = -a;
    }
    return a;
}

// Bilinear read of the prefiltered map at `map` along d (src/scene/light.rs,
// EnvironmentMap::lookup): columns wrap, rows clamp.
fn prefiltered_lookup(map: u32, d: vec3<f32>) -> vec3<f32> {
    let width = table_u32(map);
    let height = table_u32(map + 1u);
    let pi = 3.141592653589793;
    let u = (precise_atan2(d.y, d.x) - pi) / (-2.0 * pi);
    let v = (precise_atan2(length(d.xy), d.z) - pi) / (-pi);
    let x = u * f32(width) - 0.5;
    let y = clamp((1.0 - v) * f32(height) - 0.5, 0.0, f32(height - 1u));
    let x0 = floor(x);
    let y0 = floor(y);
    let w = i32(width);
    let c0 = u32((i32(x0) % w + w) % w);
    let c1 = u32((i32(x0) + 1 + w) % w);
    let r0 = u32(y0);
    let r1 = min(r0 + 1u, height - 1u);
    let top = mix(map_texel(map, width, c0, r0), map_texel(map, width, c1, r0), x - x0);
    let bottom = mix(map_texel(map, width, c0, r1), map_texel(map, width, c1, r1), x - x0);
    return mix(top, bottom, y - y0);
}

fn map_texel(map: u32, width: u32, column: u32, row: u32) -> vec3<f32> {
    let i = map + 2u + 3u * (row * width + column);
    return vec3<f32>(tables[i], tables[i + 1u], tables[i + 2u]);
}
//#endif

//#if SUNS
// The sharp lights' diffuse and glossy radiance at p (kernel.rs, sunlit; sun.rs): each
// sun's and point lamp's disk integral times the mean over its directions of visibility
// times the cosine lobe, and times the glossy lobe (GGX's BRDF, or the Phong lobe about
// r), scaled by the lamps' scale table for a prefiltered one (glossy.rs,
// lamp_scale_table).
fn sunlit(p: vec3<f32>, n: vec3<f32>, object: u32, r: vec3<f32>, material: GpuMaterial, diffuse: ptr<function, vec3<f32>>, specular: ptr<function, vec3<f32>>) {
    var albedo = 1.0;
    if material.kind == MATERIAL_PHONG && lobe_kind(material) != LOBE_SH {
        albedo = albedo_lookup(material.sharp_tables + GpuLobeHead_FLOATS + DISK_DIRECTIONS + ALBEDO_ENTRIES, dot(n, r));
    }
    for (var s = 0u; s < SUN_COUNT; s++) {
        let sun = load_GpuSun(T_SUNS + GpuSun_FLOATS * s);
        add_disk_light(p, n, object, r, material, albedo, sun.axis.xyz, sun.axis.w, sun.integral.w, 3.0e38, sun.integral.xyz, sun.shadow_map, sun.drift, diffuse, specular);
    }
    for (var s = 0u; s < POINT_COUNT; s++) {
        // The lamp's disk seen from p (src/scene/light.rs, PointLight::seen_from).
        let lamp = load_GpuPointLamp(T_POINTS + GpuPointLamp_FLOATS * s);
        let d = lamp.position.xyz - p;
        let radius = lamp.position.w;
        let intensity = lamp.intensity.xyz;
        let distance = length(d);
        var axis = n;
        if distance > 0.0 {
            axis = d / distance;
        }
        let r2 = radius * radius;
        let d2 = max(distance * distance, POINT_NEAREST * POINT_NEAREST);
        var sin2 = min(r2 / d2, 1.0);
        var spread = max(d2, r2);
        if lamp.intensity.w > 0.5 {
            sin2 = r2 / (d2 + r2);
            spread = d2 + r2;
        }
        var half_angle = asin(sqrt(sin2));
        var one_minus_cos = sin2 / (1.0 + sqrt(max(1.0 - sin2, 0.0)));
        if half_angle < POINT_HALF_ANGLE_MIN {
            half_angle = POINT_HALF_ANGLE_MIN;
            one_minus_cos = 2.0 * pow(sin(0.5 * POINT_HALF_ANGLE_MIN), 2.0);
        }
        // SunLight::disk_integral of the lamp's irradiance, intensity / spread.
        let integral = min(intensity / spread, vec3<f32>(3.0e38)) * (2.0 / (2.0 - one_minus_cos));
        let patch_radius = half_angle / sqrt(f32(DISK_DIRECTIONS));
        add_disk_light(p, n, object, r, material, albedo, axis, one_minus_cos, patch_radius, distance, integral, NO_MAP, 0.0, diffuse, specular);
    }
}

// One disk light's share (kernel.rs, sunlit's loop body): `integral` is the disk's
// radiance times its solid angle, `reach` its distance (3e38 for a sun); a sun's shadow
// map at `shadow_map` (NO_MAP for none), its rays drifting `drift` per unit of depth.
fn add_disk_light(p: vec3<f32>, n: vec3<f32>, object: u32, r: vec3<f32>, material: GpuMaterial, albedo: f32, axis: vec3<f32>, one_minus_cos: f32, patch_radius: f32, reach: f32, integral: vec3<f32>, shadow_map: u32, drift: f32, diffuse: ptr<function, vec3<f32>>, specular: ptr<function, vec3<f32>>) {
    let glossy = material.kind == MATERIAL_PHONG;
    let ggx = glossy && lobe_kind(material) == LOBE_GGX;
    let n_v = dot(n, r);
    let v = 2.0 * n_v * n - r;
    var disk = disk_around(axis, one_minus_cos);
    let blocked = disk_blocked(&disk, p, n, object, axis, one_minus_cos, patch_radius, reach, true, true, shadow_map, drift);
    var cosine = 0.0;
    var lobe = 0.0;
    // GGX smooth over an open disk takes its value at the axis (glossy.rs,
    // smooth_over_disk).
    var at_axis = false;
    if ggx {
        var open = true;
        for (var q = 0u; q < DISK_QUADS; q++) {
            open = open && all(blocked[q] == vec4<f32>(0.0));
        }
        let width = load_GpuLobeHead(material.sharp_tables).width;
        let widened = width * width + 0.25 * patch_radius * patch_radius;
        let least = SMOOTH_OVER_DISK * one_minus_cos;
        let n_axis = dot(n, axis);
        let seen_at = max(n_v, 0.0);
        at_axis = open && widened * seen_at * seen_at >= least && n_axis * n_axis >= least;
        if at_axis {
            let value = widened_ggx_lit(material, patch_radius, n_v, vec4<f32>(n_axis), vec4<f32>(dot(v, axis)));
            lobe = value.x * f32(DISK_DIRECTIONS);
        }
    }
    for (var q = 0u; q < DISK_QUADS; q++) {
        let visible = 1.0 - blocked[q];
        let n_w = n.x * disk.x[q] + n.y * disk.y[q] + n.z * disk.z[q];
        cosine += dot(visible, max(n_w, vec4<f32>(0.0)));
        if ggx && !at_axis {
            lobe += dot(visible, widened_ggx_lit(material, patch_radius, n_v, n_w, v.x * disk.x[q] + v.y * disk.y[q] + v.z * disk.z[q]));
        } else if glossy && !ggx {
            lobe += dot(visible, widened_phong_value(material, patch_radius, r.x * disk.x[q] + r.y * disk.y[q] + r.z * disk.z[q]));
        }
    }
    let mean = 1.0 / f32(DISK_DIRECTIONS);
    *diffuse += integral * (cosine * mean / 3.141592653589793) * material.albedo.xyz;
    if glossy {
        *specular += integral * (lobe * mean * albedo) * material.specular.xyz;
    }
}
//#endif

@compute @workgroup_size(WORKGROUP_SIZE)
fn shade(@builtin(global_invocation_id) id: vec3<u32>) {
    let point = id.x;
    if point >= params.point_count {
        return;
    }
    let record = points[point];
    let a = record.position_slot;
    let slot = bitcast<u32>(a.w);
    var diffuse = vec3<f32>(0.0);
    var specular = vec3<f32>(0.0);
    var terms = vec3<f32>(1.0);
    if slot != SLOT_NONE {
        let n = record.normal.xyz;
        let object = bitcast<u32>(record.normal.w);
        var caps: array<f32, COUNT_CAP>;
        var horizons: array<f32, DIRECTIONS>;
        var field: array<f32, COUNT_CAP>;
        var from_grid = false;
        var field_weight = 0.0;
//#if GRID
        // A Phong lobe's specular occlusion reads the horizons.
        let glossy = slot != SLOT_UNKNOWN && materials[slot].kind == MATERIAL_PHONG;
        from_grid = grid_at(point, a.xyz, n, object, record.reflected.w > 0.5, glossy, &horizons, &caps, &field, &field_weight);
//#endif
        var v = visibility(a.xyz, n, object, from_grid, &horizons, &caps, &field, field_weight);
        if slot != SLOT_UNKNOWN {
            let material = materials[slot];
            let lit_diffuse = lit(&v, T_DIFFUSE, n);
            var diffuse_light = open_corrected(lit_diffuse, n);
//#if BLOCKERS
            if CAP_DETAIL {
                diffuse_light = max(diffuse_light - hidden_detail(a.xyz, n, object) / 3.141592653589793, vec3<f32>(0.0));
            }
//#endif
            diffuse = diffuse_light * material.albedo.xyz;
//#if PHONG
            if material.kind == MATERIAL_PHONG && enabled(FEATURE_PHONG) {
                let reflected = record.reflected.xyz;
                var prefiltered = false;
//#if PREFILTERED
                if material.sharp_map != NO_MAP {
                    // The log-SH occlusion's visibility: the caps and the unfolded horizons.
                    var occlusion = caps;
//#if HEIGHTFIELD
                    if enabled(FEATURE_HEIGHTFIELD) && load_GpuLobeHead(material.sharp_tables).cone_share < 1.0 {
                        add_horizons(a.xyz, n, false, from_grid, &horizons, &occlusion);
                        // Only what rises above the horizontal (kernel.rs, add_visibility_parts).
                        for (var i = 0u; i < COUNT; i++) {
                            occlusion[i] -= tables[T_BELOW_HORIZONTAL + i];
                        }
                    }
//#endif
                    specular = prefiltered_glossy(&occlusion, material, a.xyz, n, object, reflected) * material.specular.xyz;
                    prefiltered = true;
                }
//#endif
                if !prefiltered {
                    specular = lit(&v, material.phong_lobe, reflected) * material.specular.xyz;
                }
            }
//#endif
//#if PASSES
            // The visibility terms (src/shade/kernel/pixel_passes.rs): diffuse light with the
            // height field, the blockers or both, over the unoccluded receiver's.
            var unoccluded: array<f32, COUNT_CAP>;
            if TANGENT_OCCLUSION {
                add_tangent(n, &unoccluded);
            }
            add_ground(a.xyz, &unoccluded);
            let lit_unoccluded = lit(&unoccluded, T_DIFFUSE, n);
            let combined = luminance_ratio(lit_diffuse, lit_unoccluded);
            var has_heightfield = false;
//#if HEIGHTFIELD
            has_heightfield = enabled(FEATURE_HEIGHTFIELD);
//#endif
            let has_blockers = params.node_count > 0u;
            terms = vec3<f32>(combined, 1.0, 1.0);
            if has_heightfield && !has_blockers {
                terms.y = combined;
            } else if has_blockers && !has_heightfield {
                terms.z = combined;
            } else if has_blockers && has_heightfield {
                // Log vectors add: the height field alone is all but the caps.
                var blockers = unoccluded;
                var heightfield = v;
                for (var i = 0u; i < COUNT; i++) {
                    blockers[i] += caps[i];
                    heightfield[i] -= caps[i];
                }
                terms.y = luminance_ratio(lit(&heightfield, T_DIFFUSE, n), lit_unoccluded);
                terms.z = luminance_ratio(lit(&blockers, T_DIFFUSE, n), lit_unoccluded);
            }
//#endif
//#if SUNS
            sunlit(a.xyz, n, object, record.reflected.xyz, material, &diffuse, &specular);
//#endif
        }
    }
    shaded[point] = GpuShaded(vec4<f32>(diffuse, 0.0), vec4<f32>(specular, 0.0), vec4<f32>(terms, 0.0));
}
