// Log-SH visibility of blockers (src/logsh/cap.rs; paper 000, Eq. 24-26, Section 4.2).

// ZH of a log depth (log(eps) in the paper) inside a cap of angular radius alpha around +Z
// (cap.rs, cap_log_zh):
// V_l = depth 2 pi K_l (P_{l-1}(cos a) - P_{l+1}(cos a)) / (2l + 1). Closed form.
fn cap_log_zh(log_depth: f32, alpha: f32) -> array<f32, ORDER_CAP> {
    let x = cos(alpha);
    var p: array<f32, ORDER_PLUS_ONE>;
    legendre(x, &p);
    var out: array<f32, ORDER_CAP>;
    out[0] = log_depth * tables[T_CAP_SCALE] * (1.0 - x);
    for (var l = 1u; l < ORDER; l++) {
        out[l] = log_depth * tables[T_CAP_SCALE + l] * (p[l - 1u] - p[l + 1u]) / f32(2u * l + 1u);
    }
    return out;
}

// The depth of a cap of fitted depth `depth` whose sphere owns `share` of its solid angle
// (fitted_depth.rs, overlapped_depth): narrow caps, which exp takes linearly, scaled by
// the share, so that overlapping proxies of one object take their union.
fn overlapped_depth(depth: f32, share: f32) -> f32 {
    let range = params.log_epsilon - tables[T_CAP_DEPTH];
    if share >= 1.0 || !(range < 0.0) {
        return depth;
    }
    let lambda = clamp((params.log_epsilon - depth) / range, 0.0, 1.0);
    return depth * (1.0 - lambda * (1.0 - share));
}

// Adds one sphere's cap as seen from receiver p with normal n (cap.rs, view_blocker):
// culled when its centre is on or behind the tangent plane (paper 000, end of Section
// 4.2); a receiver inside the sphere sees the hemisphere towards its centre. Its depth is
// the fitted one, overlapped by the sphere's share of its solid angle.
fn add_sphere(p: vec3<f32>, n: vec3<f32>, sphere: vec4<f32>, share: f32, acc: ptr<function, array<f32, COUNT_CAP>>) {
    let d = sphere.xyz - p;
    let distance = length(d);
    if !(distance > 0.0) {
        return;
    }
    let direction = d / distance;
    if dot(direction, n) <= 0.0 {
        return;
    }
    let ratio = min(sphere.w / distance, 1.0);
    let alpha = asin(ratio);
    var zonal = cap_log_zh(overlapped_depth(fitted_depth(T_CAP_DEPTH, alpha), share), alpha);
    var weight = 1.0;
    if RATIO_ATTENUATION {
        weight = ratio;
    }
    add_rotated_zonal(&zonal, weight, direction, acc);
}

// The receiver's own spheres within OWN_SPHERE_REACH radii cast nothing on it (cap.rs,
// own_sphere_holds).
fn own_sphere_holds(p: vec3<f32>, sphere: vec4<f32>) -> bool {
    let reach = OWN_SPHERE_REACH * sphere.w;
    let d = sphere.xyz - p;
    return dot(d, d) <= reach * reach;
}

// Whether a subtree whose bounds (radius r) lie at d from the receiver is behind its
// tangent plane (blocker_tree.rs, BEHIND_TOLERANCE): the skip both tree walks share.
fn behind_tangent_plane(d: vec3<f32>, r: f32, n: vec3<f32>) -> bool {
    return dot(d, n) < -r * (1.0 - BEHIND_TOLERANCE);
}

// Walks the blocker tree without a stack and adds every sphere or cluster the receiver
// sees (src/shade/blocker_tree.rs, BlockerTree::visit): subtrees wholly behind the
// tangent plane skipped, leaves seen unless they are the receiver's own and hold it,
// distant clusters seen as their equivalent sphere or dropped when negligible.
fn visit_blockers(p: vec3<f32>, n: vec3<f32>, object: u32, acc: ptr<function, array<f32, COUNT_CAP>>) {
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
                add_sphere(p, n, node.equivalent, node.share, acc);
            }
            i = node.skip;
            continue;
        }
        let distance = length(d);
        if distance > r && r <= params.cluster_ratio * distance {
            if node.equivalent.w >= NEGLIGIBLE_RATIO * length(node.equivalent.xyz - p) {
                add_sphere(p, n, node.equivalent, node.share, acc);
            }
            i = node.skip;
            continue;
        }
        i++;
    }
}
