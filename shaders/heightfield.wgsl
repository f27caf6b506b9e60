// Height-field log visibility (paper 000, Section 4.1): SN08's horizon march over the
// pyramid the pre-pass built (src/heightfield/pyramid.rs, horizon_elevations), one NLP
// slice per azimuth (src/logsh/slice.rs, Eq. 15-16) and the wedge operator M_lin between
// neighbouring slices (src/logsh/wedge.rs, Eq. 18-23). Same tables, same steps, in f32.

// Grid coordinate of world v on an axis of n samples over [lo, hi], clamped to the
// rectangle (the flat continuation).
fn grid_coordinate(v: f32, lo: f32, hi: f32, n: u32) -> f32 {
    if n <= 1u {
        return 0.0;
    }
    let last = f32(n - 1u);
    return clamp((v - lo) / (hi - lo) * last, 0.0, last);
}

fn level_sample(level: GpuLevel, column: u32, row: u32) -> f32 {
    return levels[level.offset + row * level.columns + column];
}

// Bilinear read of a level at world (x, y) (mod.rs, bilinear).
fn sample_bilinear(level: GpuLevel, x: f32, y: f32) -> f32 {
    let rect = params.heightfield_rect;
    let u = grid_coordinate(x, rect.x, rect.z, level.columns);
    let v = grid_coordinate(y, rect.y, rect.w, level.rows);
    var i0 = 0u;
    var fx = 0.0;
    if level.columns > 1u {
        i0 = min(u32(floor(u)), level.columns - 2u);
        fx = u - f32(i0);
    }
    var j0 = 0u;
    var fy = 0.0;
    if level.rows > 1u {
        j0 = min(u32(floor(v)), level.rows - 2u);
        fy = v - f32(j0);
    }
    let i1 = min(i0 + 1u, level.columns - 1u);
    let j1 = min(j0 + 1u, level.rows - 1u);
    let bottom = level_sample(level, i0, j0) + fx * (level_sample(level, i1, j0) - level_sample(level, i0, j0));
    let top = level_sample(level, i0, j1) + fx * (level_sample(level, i1, j1) - level_sample(level, i0, j1));
    return bottom + fy * (top - bottom);
}

// Uniform cubic B-spline weights at fraction t (SN08 Section 4, after Eq. 4).
fn bspline_weights(t: f32) -> vec4<f32> {
    let t2 = t * t;
    let t3 = t2 * t;
    let s = 1.0 - t;
    return vec4<f32>(s * s * s, 3.0 * t3 - 6.0 * t2 + 4.0, -3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0, t3) / 6.0;
}

// Bicubic B-spline read of a level at world (x, y), edge samples replicated.
fn sample_bspline(level: GpuLevel, x: f32, y: f32) -> f32 {
    let rect = params.heightfield_rect;
    let u = grid_coordinate(x, rect.x, rect.z, level.columns);
    let v = grid_coordinate(y, rect.y, rect.w, level.rows);
    var wx = vec4<f32>(0.25);
    var ix = 0i;
    if level.columns > 1u {
        wx = bspline_weights(u - floor(u));
        ix = i32(floor(u));
    }
    var wy = vec4<f32>(0.25);
    var iy = 0i;
    if level.rows > 1u {
        wy = bspline_weights(v - floor(v));
        iy = i32(floor(v));
    }
    let last_column = i32(level.columns) - 1;
    let last_row = i32(level.rows) - 1;
    var sum = 0.0;
    for (var r = 0; r < 4; r++) {
        let row = u32(clamp(iy - 1 + r, 0, last_row));
        var s = 0.0;
        for (var c = 0; c < 4; c++) {
            let column = u32(clamp(ix - 1 + c, 0, last_column));
            s += wx[c] * level_sample(level, column, row);
        }
        sum += wy[r] * s;
    }
    return sum;
}

fn sample_level(index: u32, x: f32, y: f32) -> f32 {
    let level = level_table[index];
    if BSPLINE_LEVELS {
        return sample_bspline(level, x, y);
    }
    return sample_bilinear(level, x, y);
}

// Distance after which the clamped footprint of (x, y) + t dir stops moving.
fn far_distance(x: f32, y: f32, dir: vec2<f32>) -> f32 {
    let rect = params.heightfield_rect;
    let level0 = level_table[0];
    var t_far = 0.0;
    if level0.columns > 1u {
        if dir.x > 0.0 {
            t_far = max(t_far, (rect.z - x) / dir.x);
        } else if dir.x < 0.0 {
            t_far = max(t_far, (rect.x - x) / dir.x);
        }
    }
    if level0.rows > 1u {
        if dir.y > 0.0 {
            t_far = max(t_far, (rect.w - y) / dir.y);
        } else if dir.y < 0.0 {
            t_far = max(t_far, (rect.y - y) / dir.y);
        }
    }
    return t_far;
}

// Maximum of the cubic B-spline through the per-step angles (SN08 Eq. 4-5), sampled at
// knots and midpoints, end values replicated (pyramid.rs, bspline_max).
fn bspline_max(omega: ptr<function, array<f32, STEP_ARRAY>>, m: u32) -> f32 {
    var best = -3.0e38;
    let last = i32(m) - 1;
    for (var i = 0; i <= last; i++) {
        let a = (*omega)[u32(clamp(i - 1, 0, last))];
        let b = (*omega)[u32(i)];
        let c = (*omega)[u32(clamp(i + 1, 0, last))];
        best = max(best, (a + 4.0 * b + c) / 6.0);
        if i < last {
            let d = (*omega)[u32(clamp(i + 2, 0, last))];
            best = max(best, (a + 23.0 * (b + c) + d) / 48.0);
        }
    }
    return best;
}

// The highest tangent any step from s on can reach (pyramid.rs, step_ceilings): a read
// of a level never rises above the height field's peak, and the margin (1e-5 of the
// terms) stays above f32's rounding. A march stops once its horizon is above it, with the
// horizon the whole march gives.
fn step_ceilings(above: f32, receiver: ptr<function, array<f32, LEVELS>>) -> array<f32, STEP_ARRAY> {
    var ceilings: array<f32, STEP_ARRAY>;
    var highest = -3.0e38;
    let peak = params.heightfield_peak;
    for (var k = 0u; k < STEPS; k++) {
        let s = STEPS - 1u - k;
        let step = steps[s];
        let start = (*receiver)[step.level] + above;
        let slack = 1e-5 * (abs(peak) + abs(start));
        let tangent = (peak - start + slack) * step.inv_distance;
        highest = max(highest, tangent + 1e-5 * abs(tangent));
        ceilings[s] = highest;
    }
    return ceilings;
}

// Horizon elevation along azimuth k from (x, y), `above` the level-0 surface, with the
// receiver terms f_L(x) of SN08 Eq. 2 per level (pyramid.rs, horizon_elevations).
fn horizon(x: f32, y: f32, above: f32, dir: vec2<f32>, reach: f32, receiver: ptr<function, array<f32, LEVELS>>, ceilings: ptr<function, array<f32, STEP_ARRAY>>) -> f32 {
    let t_far = far_distance(x, y, dir);
    // The lowest horizon (pyramid.rs, lowest_horizon): 0 unbounded, none within a lamp's
    // reach. A sun's or the environment's is 3e38, times the horizontal part of its axis
    // (above 1e-9), so at least 3e29; a lamp's is its distance.
    let floor_tan = select(0.0, -3.0e38, reach < 1.0e20);
    var max_tan = -3.0e38;
    var omega: array<f32, STEP_ARRAY>;
    var m = 0u;
    for (var s = 0u; s < STEPS; s++) {
        let step = steps[s];
        if step.distance > reach {
            break;
        }
        if !BSPLINE_SCALE_MAX && max(max_tan, floor_tan) >= (*ceilings)[s] {
            break;
        }
        let q = sample_level(step.level, x + step.distance * dir.x, y + step.distance * dir.y);
        let tangent = (q - (*receiver)[step.level] - above) * step.inv_distance;
        if BSPLINE_SCALE_MAX {
            omega[m] = atan(tangent);
        } else {
            max_tan = max(max_tan, tangent);
        }
        m++;
        if step.distance > t_far {
            break;
        }
    }
    var elevation = atan(max_tan);
    if BSPLINE_SCALE_MAX {
        elevation = bspline_max(&omega, m);
    }
    return max(elevation, atan(floor_tan));
}

// NLP coefficients of log(eps) below elevation sigma (slice.rs, nlp_slice; Eq. 15-16).
fn nlp_slice(log_epsilon: f32, sigma: f32) -> array<f32, ORDER_CAP> {
    let s = clamp(sin(sigma), -1.0, 1.0);
    var p: array<f32, ORDER_PLUS_ONE>;
    legendre(s, &p);
    var out: array<f32, ORDER_CAP>;
    out[0] = log_epsilon * tables[T_NLP_SCALE] * (s + 1.0);
    for (var l = 1u; l < ORDER; l++) {
        out[l] = log_epsilon * tables[T_NLP_SCALE + l] * (p[l + 1u] - p[l - 1u]) / f32(2u * l + 1u);
    }
    return out;
}

// The band table's row for a pixel whose horizons cover `coverage` of the azimuths, and
// the weight of the row above it (fitted_depth.rs, band_depths_for): rows of falling
// coverage, interpolated in log(coverage).
fn band_rows(coverage: f32) -> vec2<f32> {
    if BAND_ROWS == 1u || coverage >= tables[T_BAND_COVERAGE] {
        return vec2<f32>(0.0, 0.0);
    }
    var r = BAND_ROWS - 1u;
    for (var i = 1u; i < BAND_ROWS; i++) {
        if tables[T_BAND_COVERAGE + i] <= coverage {
            r = i;
            break;
        }
    }
    let wider = tables[T_BAND_COVERAGE + r - 1u];
    let own = tables[T_BAND_COVERAGE + r];
    return vec2<f32>(f32(r), clamp(log(max(coverage, own) / own) / log(wider / own), 0.0, 1.0));
}

// The fitted depth of a band of width `width` in the rows `rows` (band_rows).
fn band_depth(width: f32, rows: vec2<f32>) -> f32 {
    let r = u32(rows.x);
    let own = fitted_depth(T_BAND_DEPTH + r * (DEPTH_INTERVALS + 1u), width);
    if r == 0u {
        return own;
    }
    let wider = fitted_depth(T_BAND_DEPTH + (r - 1u) * (DEPTH_INTERVALS + 1u), width);
    return own + rows.y * (wider - own);
}

// A slice with its horizon band at the fitted depth (fitted_depth.rs, banded_slice):
// log(eps) up to `base`, the band from `base` to `sigma` at the depth for its width in
// the rows `rows`.
fn banded_slice(log_epsilon: f32, base: f32, sigma: f32, rows: vec2<f32>) -> array<f32, ORDER_CAP> {
    if sigma <= base {
        return nlp_slice(log_epsilon, sigma);
    }
    let below = nlp_slice(1.0, base);
    var out = nlp_slice(1.0, sigma);
    let depth = band_depth(sigma - base, rows);
    for (var l = 0u; l < ORDER; l++) {
        out[l] = log_epsilon * below[l] + depth * (out[l] - below[l]);
    }
    return out;
}

// acc += wedge k between slices `first` and `second`, rotated about z by phi_k
// (wedge.rs, accumulate; Eq. 20-23).
fn add_wedge(k: u32, first: ptr<function, array<f32, ORDER_CAP>>, second: ptr<function, array<f32, ORDER_CAP>>, acc: ptr<function, array<f32, COUNT_CAP>>) {
    var wedge: array<f32, COUNT_CAP>;
    for (var i = 0u; i < COUNT; i++) {
        let row = T_WEDGE + i * 2u * ORDER;
        var sum = 0.0;
        for (var j = 0u; j < ORDER; j++) {
            sum += tables[row + j] * (*first)[j] + tables[row + ORDER + j] * (*second)[j];
        }
        wedge[i] = sum;
    }
    // z rotation by phi_k: the (y_l^m, y_l^-m) pair turns by m phi_k (rotation.rs).
    let phases = T_PHASES + k * 2u * ORDER;
    for (var l = 1u; l < ORDER; l++) {
        for (var m = 1u; m <= l; m++) {
            let c = tables[phases + 2u * m];
            let s = tables[phases + 2u * m + 1u];
            let ip = l * (l + 1u) + m;
            let im = l * (l + 1u) - m;
            let a = wedge[ip];
            let b = wedge[im];
            wedge[ip] = a * c - b * s;
            wedge[im] = a * s + b * c;
        }
    }
    for (var i = 0u; i < COUNT; i++) {
        (*acc)[i] += wedge[i];
    }
}

// Where the march from p starts (pyramid.rs, receiver_of): its height above level 0, the
// receiver terms per level and the step ceilings; false where p is not finite or the
// pyramid has no steps, whose horizons are all 0.
fn march_start(p: vec3<f32>, above: ptr<function, f32>, receiver: ptr<function, array<f32, LEVELS>>, ceilings: ptr<function, array<f32, STEP_ARRAY>>) -> bool {
    if STEPS == 0u || !all(abs(p) < vec3<f32>(3.0e38)) {
        return false;
    }
    *above = max(p.z - sample_bilinear(level_table[0], p.x, p.y), 0.0);
    for (var level = 0u; level < LEVELS; level++) {
        (*receiver)[level] = sample_level(level, p.x, p.y);
    }
    *ceilings = step_ceilings(*above, receiver);
    return true;
}

fn azimuth(k: u32) -> vec2<f32> {
    return vec2<f32>(tables[T_AZIMUTHS + 2u * k], tables[T_AZIMUTHS + 2u * k + 1u]);
}

// The band of azimuth k under the horizon at elevation sigma, as (base, top): from the
// horizontal (from the tangent plane when `fold_tangent`) up to the horizon (kernel.rs,
// add_horizon_slices).
fn horizon_band(k: u32, sigma: f32, n: vec3<f32>, fold_tangent: bool) -> vec2<f32> {
    if fold_tangent {
        let dir = azimuth(k);
        let tangent_elevation = atan(-(n.x * dir.x + n.y * dir.y) / n.z);
        return vec2<f32>(tangent_elevation, max(sigma, tangent_elevation));
    }
    return vec2<f32>(0.0, sigma);
}

// The height field's log visibility at p, normal n (kernel.rs, add_visibility): one
// horizon per azimuth, then the slices from them (add_given_horizons).
fn add_heightfield(p: vec3<f32>, n: vec3<f32>, fold_tangent: bool, log_epsilon: f32, acc: ptr<function, array<f32, COUNT_CAP>>) {
    var above = 0.0;
    var receiver: array<f32, LEVELS>;
    var ceilings: array<f32, STEP_ARRAY>;
    let marchable = march_start(p, &above, &receiver, &ceilings);
    var sigmas: array<f32, DIRECTIONS>;
    for (var k = 0u; k < DIRECTIONS; k++) {
        sigmas[k] = 0.0;
        if marchable {
            sigmas[k] = horizon(p.x, p.y, above, azimuth(k), 3.0e38, &receiver, &ceilings);
        }
    }
    add_given_horizons(&sigmas, n, fold_tangent, log_epsilon, acc);
}

// The height field's log visibility from given horizon elevations: each band at the
// depth fitted for its width and the horizons' coverage (kernel.rs, add_horizon_slices;
// fitted_depth.rs, horizon_coverage), wedges between neighbouring slices, the tangent
// plane folded into the horizons when `fold_tangent`.
fn add_given_horizons(sigmas: ptr<function, array<f32, DIRECTIONS>>, n: vec3<f32>, fold_tangent: bool, log_epsilon: f32, acc: ptr<function, array<f32, COUNT_CAP>>) {
    var bands: array<vec2<f32>, DIRECTIONS>;
    var blocked = 0.0;
    var most = 0.0;
    for (var k = 0u; k < DIRECTIONS; k++) {
        bands[k] = horizon_band(k, (*sigmas)[k], n, fold_tangent);
        let share = pow(sin(max(bands[k].y - bands[k].x, 0.0)), 2.0);
        blocked += share;
        most = max(most, share);
    }
    let rows = band_rows(select(1.0, blocked / (most * f32(DIRECTIONS)), most > 0.0));
    var first: array<f32, ORDER_CAP>;
    var previous: array<f32, ORDER_CAP>;
    for (var k = 0u; k < DIRECTIONS; k++) {
        var slice = banded_slice(log_epsilon, bands[k].x, bands[k].y, rows);
        if k == 0u {
            first = slice;
        } else {
            add_wedge(k - 1u, &previous, &slice, acc);
        }
        previous = slice;
    }
    add_wedge(DIRECTIONS - 1u, &previous, &first, acc);
}

//#if GRID
// The tangents of the horizons' elevations at p, one per azimuth, into the visibility
// grid's record at `record` (visibility_grid.rs; pyramid.rs, horizon_tangents).
fn store_horizon_tangents(p: vec3<f32>, record: u32) {
    var above = 0.0;
    var receiver: array<f32, LEVELS>;
    var ceilings: array<f32, STEP_ARRAY>;
    let marchable = march_start(p, &above, &receiver, &ceilings);
    for (var k = 0u; k < GRID_HORIZONS; k++) {
        var sigma = 0.0;
        if marchable {
            sigma = horizon(p.x, p.y, above, azimuth(k), 3.0e38, &receiver, &ceilings);
        }
        grid[record + k] = tan(sigma);
    }
}

//#endif
