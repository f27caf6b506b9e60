// Real spherical harmonics (src/sh/basis.rs, src/sh/rotation.rs): the same recurrences
// as the CPU path, with the normalisation constants read from the host's tables.
// Convention: no Condon-Shortley phase, index l(l+1)+m, band 1 = sqrt(3/4pi) (y, z, x).

fn table_u32(i: u32) -> u32 {
    return bitcast<u32>(tables[i]);
}

// The log depth for an angle (a cap's radius, a band's width), interpolated linearly in
// the fitted table at `table` (src/shade/fitted_depth.rs, depth_at).
fn fitted_depth(table: u32, angle: f32) -> f32 {
    let x = clamp(angle / 1.5707963, 0.0, 1.0) * f32(DEPTH_INTERVALS);
    let k = min(u32(x), DEPTH_INTERVALS - 1u);
    let t = x - f32(k);
    let below = tables[table + k];
    return below + t * (tables[table + k + 1u] - below);
}

// y_i(dir) for the COUNT basis functions (basis.rs, eval_basis): associated Legendre
// polynomials by upward recurrence in l, (x + iy)^m for the azimuthal part.
fn eval_basis(d: vec3<f32>, y: ptr<function, array<f32, COUNT_CAP>>) {
    var cm = 1.0;
    var sm = 0.0;
    for (var m = 0u; m < ORDER; m++) {
        var q_prev = 0.0;
        var q = tables[T_DOUBLE_FACTORIAL + m];
        for (var l = m; l < ORDER; l++) {
            if l == m + 1u {
                q_prev = q;
                q = d.z * f32(2u * m + 1u) * q_prev;
            } else if l > m + 1u {
                let next = (f32(2u * l - 1u) * d.z * q - f32(l + m - 1u) * q_prev) / f32(l - m);
                q_prev = q;
                q = next;
            }
            let centre = l * (l + 1u);
            let k = tables[T_SH_NORMALISATION + centre + m];
            if m == 0u {
                (*y)[centre] = k * q;
            } else {
                (*y)[centre + m] = k * q * cm;
                (*y)[centre - m] = k * q * sm;
            }
        }
        let c = cm * d.x - sm * d.y;
        sm = cm * d.y + sm * d.x;
        cm = c;
    }
}

// Legendre polynomials P_0..P_{ORDER} at z (basis.rs, legendre).
fn legendre(z: f32, p: ptr<function, array<f32, ORDER_PLUS_ONE>>) {
    (*p)[0] = 1.0;
    (*p)[1] = z;
    for (var l = 2u; l <= ORDER; l++) {
        (*p)[l] = (f32(2u * l - 1u) * z * (*p)[l - 1u] - f32(l - 1u) * (*p)[l - 2u]) / f32(l);
    }
}

// acc += weight * (zonal function rotated to dir) (rotation.rs, add_rotated_zonal;
// paper 000, Eq. 5).
fn add_rotated_zonal(zonal: ptr<function, array<f32, ORDER_CAP>>, weight: f32, dir: vec3<f32>, acc: ptr<function, array<f32, COUNT_CAP>>) {
    var y: array<f32, COUNT_CAP>;
    eval_basis(dir, &y);
    for (var l = 0u; l < ORDER; l++) {
        let scale = weight * tables[T_FUNK_HECKE + l] * (*zonal)[l];
        for (var i = l * l; i < (l + 1u) * (l + 1u); i++) {
            (*acc)[i] += scale * y[i];
        }
    }
}

// A zonal table of the host's (ORDER values at `offset`).
fn load_zonal(offset: u32) -> array<f32, ORDER_CAP> {
    var zonal: array<f32, ORDER_CAP>;
    for (var l = 0u; l < ORDER; l++) {
        zonal[l] = tables[offset + l];
    }
    return zonal;
}
