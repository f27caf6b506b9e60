//! `scene.json` as written: its fields, and their parsing into the scene's materials,
//! lamps and light (the format contract: docs/design.md).

use super::*;

#[derive(Deserialize)]
pub(super) struct VersionProbe {
    pub(super) version: Option<serde_json::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SceneFile {
    #[allow(dead_code)]
    pub(super) version: u32,
    pub(super) frames: Option<FrameRange>,
    pub(super) gbuffer: String,
    pub(super) reflection_gbuffer: Option<String>,
    pub(super) camera: Option<String>,
    pub(super) blockers: Option<String>,
    pub(super) heightfield: Option<HeightfieldFile>,
    pub(super) ground: Option<GroundFile>,
    pub(super) materials: BTreeMap<String, MaterialFile>,
    pub(super) light: LightFile,
    pub(super) lights: Option<Vec<SharpLightFile>>,
    pub(super) channels: Option<gbuffer::ChannelOverrides>,
    pub(super) view: Option<view::ViewSpec>,
    pub(super) supersample: Option<u32>,
    pub(super) colour_passes: Option<bool>,
    pub(super) per_frame: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GroundFile {
    pub(super) height: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SharpLightFile {
    #[serde(rename = "type")]
    pub(super) kind: String,
    pub(super) direction: Option<[f64; 3]>,
    pub(super) angle: Option<f64>,
    pub(super) strength: Option<f64>,
    pub(super) position: Option<[f64; 3]>,
    pub(super) radius: Option<f64>,
    pub(super) power: Option<f64>,
    pub(super) soft_falloff: Option<bool>,
    pub(super) color: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct HeightfieldFile {
    pub(super) heights: String,
    pub(super) min: [f64; 2],
    pub(super) max: [f64; 2],
    pub(super) channel: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MaterialFile {
    #[serde(rename = "type")]
    pub(super) kind: String,
    pub(super) albedo: Option<[f64; 3]>,
    pub(super) tint: Option<[f64; 3]>,
    pub(super) specular: Option<[f64; 3]>,
    pub(super) exponent: Option<f64>,
    pub(super) fresnel: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LightFile {
    pub(super) environment: Option<String>,
    pub(super) strength: Option<f64>,
    pub(super) rotation: Option<[f64; 3]>,
    pub(super) constant: Option<[f64; 3]>,
    pub(super) sh: Option<Vec<[f64; 3]>>,
}

impl SceneFile {
    /// Every path of the file lies inside the scene directory ([`paths`]).
    pub(super) fn check_paths_inside(&self, file: &Path, dir: &Path) -> Result<(), SceneError> {
        let optional = [
            ("reflection_gbuffer", &self.reflection_gbuffer),
            ("camera", &self.camera),
            ("blockers", &self.blockers),
            ("light.environment", &self.light.environment),
            ("per_frame", &self.per_frame),
        ];
        paths::check_inside(file, dir, "gbuffer", &self.gbuffer)?;
        for (key, path) in optional {
            if let Some(path) = path {
                paths::check_inside(file, dir, key, path)?;
            }
        }
        if let Some(h) = &self.heightfield {
            paths::check_inside(file, dir, "heightfield.heights", &h.heights)?;
        }
        if let Some(lut) = self.view.as_ref().and_then(|v| v.lut.as_ref()) {
            paths::check_inside(file, dir, "view.lut.file", &lut.file.to_string_lossy())?;
        }
        Ok(())
    }
}

/// Reads a JSON file into `T`, mapping every failure to a [`SceneError`] that names the
/// file (and the line, for syntax and schema errors).
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(file: &Path, what: &str) -> Result<T, SceneError> {
    let text = std::fs::read_to_string(file).map_err(|e| SceneError::io(file, what, e))?;
    serde_json::from_str(&text).map_err(|e| SceneError::json(file, e))
}

pub(super) fn colour(file: &Path, what: &str, c: [f64; 3]) -> Result<[f32; 3], SceneError> {
    for v in c {
        if !v.is_finite() {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: what.to_string() });
        }
        if v < 0.0 {
            return Err(SceneError::invalid(
                file,
                format!("{what} has a negative component {v}; colours must be >= 0"),
            ));
        }
    }
    Ok([c[0] as f32, c[1] as f32, c[2] as f32])
}

/// A material entry: its index, the material, and a `phong` material's reflectance at
/// normal incidence where the entry gives it (`fresnel`).
pub(super) fn parse_material(
    file: &Path,
    key: &str,
    m: &MaterialFile,
) -> Result<(u32, Material, Option<f64>), SceneError> {
    let index: u32 = key.trim().parse().map_err(|_| {
        SceneError::invalid(file, format!("material key \"{key}\" is not a material index (a whole number >= 1)"))
    })?;
    if index == 0 {
        return Err(SceneError::invalid(file, "material index 0 is the background and cannot be defined"));
    }
    let name = format!("material {index}");
    let allowed: &[&str] = match m.kind.as_str() {
        "heightfield" | "diffuse" => &["albedo"],
        "water" => &["tint"],
        "phong" => &["albedo", "specular", "exponent"],
        other => {
            return Err(SceneError::invalid(
                file,
                format!("{name}: unknown type \"{other}\" (expected heightfield, water, diffuse or phong)"),
            ))
        }
    };
    let present = [
        ("albedo", m.albedo.is_some()),
        ("tint", m.tint.is_some()),
        ("specular", m.specular.is_some()),
        ("exponent", m.exponent.is_some()),
    ];
    for (k, is) in present {
        if is && !allowed.contains(&k) {
            return Err(SceneError::invalid(file, format!("{name}: key \"{k}\" does not belong to type {}", m.kind)));
        }
        if !is && allowed.contains(&k) {
            return Err(SceneError::invalid(file, format!("{name}: type {} needs key \"{k}\"", m.kind)));
        }
    }
    let fresnel = match m.fresnel {
        Some(_) if m.kind != "phong" => {
            return Err(SceneError::invalid(
                file,
                format!("{name}: key \"fresnel\" does not belong to type {}", m.kind),
            ))
        }
        Some(f) if !f.is_finite() => {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("{name} fresnel") })
        }
        Some(f) if !(0.0..=1.0).contains(&f) => {
            return Err(SceneError::invalid(file, format!("{name}: fresnel {f} is not a reflectance from 0 to 1")))
        }
        f => f,
    };
    let get = |k: &str, v: Option<[f64; 3]>| colour(file, &format!("{name} {k}"), v.expect("checked above"));
    let material = match m.kind.as_str() {
        "heightfield" => Material::Heightfield { albedo: get("albedo", m.albedo)? },
        "diffuse" => Material::Diffuse { albedo: get("albedo", m.albedo)? },
        "water" => Material::Water { tint: get("tint", m.tint)? },
        _ => {
            let exponent = m.exponent.expect("checked above");
            if !exponent.is_finite() {
                return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("{name} exponent") });
            }
            if exponent <= 0.0 {
                return Err(SceneError::invalid(file, format!("{name}: exponent {exponent} must be > 0")));
            }
            Material::Phong {
                albedo: get("albedo", m.albedo)?,
                specular: get("specular", m.specular)?,
                exponent: exponent as f32,
            }
        }
    };
    Ok((index, material, fresnel))
}

/// One entry of `lights`.
pub(super) enum Lamp {
    Sun(SunLight),
    Point(PointLight),
}

pub(super) fn parse_lamp(file: &Path, i: usize, l: &SharpLightFile) -> Result<Lamp, SceneError> {
    let name = format!("lights[{i}]");
    let keys = [
        ("direction", l.direction.is_some()),
        ("angle", l.angle.is_some()),
        ("strength", l.strength.is_some()),
        ("position", l.position.is_some()),
        ("radius", l.radius.is_some()),
        ("power", l.power.is_some()),
        ("soft_falloff", l.soft_falloff.is_some()),
    ];
    let allowed: &[&str] = match l.kind.as_str() {
        "sun" => &["direction", "angle", "strength"],
        "point" => &["position", "radius", "power", "soft_falloff"],
        other => {
            return Err(SceneError::invalid(file, format!("{name}: unknown type \"{other}\" (expected sun or point)")))
        }
    };
    if let Some((key, _)) = keys.iter().find(|(k, present)| *present && !allowed.contains(k)) {
        return Err(SceneError::invalid(file, format!("{name}: key \"{key}\" does not belong to a {}", l.kind)));
    }
    let missing = |key: &str| SceneError::invalid(file, format!("{name}: {} needs \"{key}\"", l.kind));
    let non_finite = |what: &str| SceneError::NonFinite { file: file.to_path_buf(), what: format!("{name} {what}") };
    let color = match l.color {
        Some(c) => colour(file, &format!("{name} color"), c)?,
        None => [1.0; 3],
    };
    // Strength and power are f32 in shading: finite, >= 0, and within f32.
    let amount = |key: &str, value: f64| {
        if !value.is_finite() {
            Err(non_finite(key))
        } else if !(0.0..=f64::from(f32::MAX)).contains(&value) {
            Err(SceneError::invalid(file, format!("{name}: {key} {value} must be >= 0 and at most {:e}", f32::MAX)))
        } else {
            Ok(value as f32)
        }
    };
    if l.kind == "point" {
        let position = l.position.ok_or_else(|| missing("position"))?;
        let radius = l.radius.ok_or_else(|| missing("radius"))?;
        if position.iter().chain([&radius]).any(|v| !v.is_finite()) {
            return Err(non_finite("position or radius"));
        }
        if radius < 0.0 {
            return Err(SceneError::invalid(file, format!("{name}: radius {radius} must be >= 0")));
        }
        let power = amount("power", l.power.ok_or_else(|| missing("power"))?)?;
        let soft_falloff = l.soft_falloff.unwrap_or(true);
        return Ok(Lamp::Point(PointLight { position, radius, power, color, soft_falloff }));
    }
    let direction = l.direction.ok_or_else(|| missing("direction"))?;
    let angle = l.angle.ok_or_else(|| missing("angle"))?;
    if direction.iter().chain([&angle]).any(|v| !v.is_finite()) {
        return Err(non_finite("direction or angle"));
    }
    let strength = amount("strength", l.strength.ok_or_else(|| missing("strength"))?)?;
    let length = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(length > 0.0) {
        return Err(SceneError::invalid(file, format!("{name}: direction {direction:?} has no length")));
    }
    if !(angle > 0.0 && angle <= 180.0) {
        return Err(SceneError::invalid(file, format!("{name}: angle {angle} must be in (0, 180] degrees")));
    }
    Ok(Lamp::Sun(SunLight {
        direction: direction.map(|v| v / length),
        half_angle: (0.5 * angle).to_radians(),
        strength,
        color,
    }))
}

pub(super) fn parse_light(file: &Path, l: &LightFile) -> Result<LightSpec, SceneError> {
    let count = l.environment.is_some() as u8 + l.constant.is_some() as u8 + l.sh.is_some() as u8;
    if count != 1 {
        return Err(SceneError::invalid(
            file,
            "light must have exactly one of \"environment\", \"constant\" or \"sh\"",
        ));
    }
    if l.strength.is_some() && l.environment.is_none() {
        return Err(SceneError::invalid(file, "light: \"strength\" goes only with \"environment\""));
    }
    if l.rotation.is_some() && l.environment.is_none() {
        return Err(SceneError::invalid(file, "light: \"rotation\" goes only with \"environment\""));
    }
    let rotation = l.rotation.unwrap_or([0.0; 3]);
    if rotation.iter().any(|v| !v.is_finite()) {
        return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "light rotation".into() });
    }
    if let Some(path) = &l.environment {
        let strength = l.strength.unwrap_or(1.0);
        if !strength.is_finite() {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "light strength".into() });
        }
        if strength < 0.0 {
            return Err(SceneError::invalid(file, format!("light strength {strength} must be >= 0")));
        }
        return Ok(LightSpec::Environment { path: PathTemplate(path.clone()), strength: strength as f32, rotation });
    }
    if let Some(c) = l.constant {
        return Ok(LightSpec::Constant(colour(file, "light constant", c)?));
    }
    let sh = l.sh.as_ref().expect("one of the three is present");
    let n = (sh.len() as f64).sqrt().round() as usize;
    if sh.is_empty() || n * n != sh.len() || n > light::MAX_SH_LIGHT_ORDER {
        return Err(SceneError::invalid(
            file,
            format!(
                "light sh has {} coefficients; it needs order^2 (1, 4, 9, 16, ...), order at most {}",
                sh.len(),
                light::MAX_SH_LIGHT_ORDER
            ),
        ));
    }
    for (i, c) in sh.iter().enumerate() {
        if c.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("light sh coefficient {i}") });
        }
    }
    Ok(LightSpec::Sh(sh.clone()))
}
