//! A frame of a scene: read whole ([`Scene::frame`]), or opened with everything but its
//! G-buffers' pixels, which are read a band of rows at a time ([`Scene::open_frame`],
//! `logsh render`'s bands).

use super::*;

/// One frame's data, everything the shading of that frame reads.
#[derive(Clone, Debug)]
pub struct Frame {
    pub number: i64,
    pub gbuffer: GBuffer,
    /// Present when `scene.json` has `reflection_gbuffer`.
    pub reflection: Option<GBuffer>,
    /// Present when `scene.json` has `camera`.
    pub camera: Option<Camera>,
    /// Empty when `scene.json` has no `blockers`.
    pub blockers: Vec<Sphere>,
    /// The suns' shadow maps of the blocker meshes (`sun_shadows` in the blockers file).
    pub sun_shadows: Vec<Arc<SunShadowMap>>,
    pub height_map: Option<Arc<HeightMap>>,
    pub light: Arc<Light>,
    /// The CRC-32 of the light's map file as it was read, `None` without a map.
    pub light_file_crc: Option<u32>,
    /// The scene's suns (`lights` in scene.json).
    pub suns: Vec<SunLight>,
    /// The scene's point lamps (`lights` in scene.json).
    pub points: Vec<PointLight>,
    /// The scene's ground plane height (`ground` in scene.json).
    pub ground: Option<f64>,
    /// G-buffer samples per output pixel along each axis ([`Scene::supersample`]).
    pub supersample: usize,
}

/// A frame whose files are read but for the pixels of its G-buffers ([`Scene::open_frame`]).
pub struct OpenFrame {
    pub number: i64,
    gbuffer: GBufferFile,
    reflection: Option<GBufferFile>,
    camera: Option<Camera>,
    blockers: Vec<Sphere>,
    sun_shadows: Vec<Arc<SunShadowMap>>,
    height_map: Option<Arc<HeightMap>>,
    light: Arc<Light>,
    light_file_crc: Option<u32>,
    suns: Vec<SunLight>,
    points: Vec<PointLight>,
}

/// The surface pixels over the height field, and how many of them lie buried below it
/// ([`HeightMap::buried_share`]), counted over a frame's bands.
#[derive(Clone, Copy, Debug, Default)]
pub struct BuriedCount {
    pub over: usize,
    pub buried: usize,
}

impl OpenFrame {
    /// The G-buffer's width and height.
    pub fn size(&self) -> (usize, usize) {
        (self.gbuffer.width, self.gbuffer.height)
    }

    /// The frame with the G-buffers' rows `rows` (starting on a multiple of 16, ending
    /// on one or at the bottom; all of them for the whole frame). A water pixel needs a
    /// reflection G-buffer.
    pub fn rows(&self, scene: &Scene, rows: std::ops::Range<usize>) -> Result<Frame, SceneError> {
        let gbuffer = self.gbuffer.read_rows(&scene.materials, rows.clone())?;
        let reflection = self.reflection.as_ref().map(|r| r.read_rows(&scene.materials, rows)).transpose()?;
        if reflection.is_none() {
            let water: Vec<u32> =
                scene.materials.iter().filter(|(_, m)| matches!(m, Material::Water { .. })).map(|(&i, _)| i).collect();
            if let Some(p) = gbuffer.material.iter().position(|m| water.contains(m)) {
                return Err(SceneError::invalid(
                    &gbuffer.file,
                    format!(
                        "pixel ({}, {}) is water (material {}) but scene.json has no \"reflection_gbuffer\"",
                        p % gbuffer.width,
                        gbuffer.first_row + p / gbuffer.width,
                        gbuffer.material[p]
                    ),
                ));
            }
        }
        Ok(Frame {
            number: self.number,
            gbuffer,
            reflection,
            camera: self.camera.clone(),
            blockers: self.blockers.clone(),
            sun_shadows: self.sun_shadows.clone(),
            height_map: self.height_map.clone(),
            light: self.light.clone(),
            light_file_crc: self.light_file_crc,
            suns: self.suns.clone(),
            points: self.points.clone(),
            ground: scene.ground,
            supersample: scene.supersample,
        })
    }

    /// Adds the surface pixels of `gbuffer` (rows of this frame's) to `count`.
    pub fn count_buried(&self, gbuffer: &GBuffer, count: &mut BuriedCount) {
        if let Some(map) = &self.height_map {
            let (over, buried) = map.buried_pixels(gbuffer);
            count.over += over;
            count.buried += buried;
        }
    }

    /// Refuses a frame whose surface pixels over the height field, counted over all its
    /// rows, lie buried below it: the map is not this frame's terrain.
    pub fn check_buried(&self, scene: &Scene, count: BuriedCount) -> Result<(), SceneError> {
        let share = (count.over > 0).then(|| count.buried as f64 / count.over as f64);
        let (Some(share), Some(h)) = (share, &scene.heightfield) else { return Ok(()) };
        if share <= heightmap::MOST_BURIED {
            return Ok(());
        }
        Err(SceneError::invalid(
            &self.gbuffer_file(),
            format!(
                "{:.0} % of the surface pixels over the height field lie more than {} sample spacing(s) \
                 below {}: the map is not this frame's terrain. A terrain that moves needs one map per \
                 frame (\"heightmap.####.exr\", which the exporter writes when it moves)",
                100.0 * share,
                heightmap::BURIED_DEPTH,
                h.heights.for_frame(self.number)
            ),
        ))
    }

    /// The G-buffer file.
    pub fn gbuffer_file(&self) -> PathBuf {
        self.gbuffer.file().to_path_buf()
    }
}

impl Scene {
    /// Reads and validates everything of `frame`.
    ///
    /// Checks, beyond those of each file: the frame lies in `frames`; the reflection
    /// G-buffer has the G-buffer's size; the camera's `resolution` equals the G-buffer
    /// size; a water pixel needs a reflection G-buffer; the surface pixels over the
    /// height field lie on it ([`OpenFrame::check_buried`]).
    pub fn frame(&self, frame: i64) -> Result<Frame, SceneError> {
        let opened = self.open_frame(frame, Reading::Whole)?;
        let whole = opened.rows(self, 0..opened.size().1)?;
        let mut buried = BuriedCount::default();
        opened.count_buried(&whole.gbuffer, &mut buried);
        opened.check_buried(self, buried)?;
        Ok(whole)
    }

    /// Reads everything of `frame` but the pixels of its G-buffers, which
    /// [`OpenFrame::rows`] reads (whole with [`Reading::Whole`], else only the blocks of
    /// the rows asked for), with the checks of [`Scene::frame`] that need no pixel.
    pub fn open_frame(&self, frame: i64, reading: Reading) -> Result<OpenFrame, SceneError> {
        self.check_frame(frame)?;
        let gfile = self.gbuffer.resolve(&self.dir, frame);
        let gbuffer = GBufferFile::open(&gfile, &self.channels, true, reading)?;
        let reflection = match &self.reflection_gbuffer {
            None => None,
            Some(t) => {
                let rfile = t.resolve(&self.dir, frame);
                let r = GBufferFile::open(&rfile, &self.channels, false, reading)?;
                if [r.width, r.height] != [gbuffer.width, gbuffer.height] {
                    return Err(SceneError::SizeMismatch {
                        file: rfile,
                        found: [r.width, r.height],
                        expected: [gbuffer.width, gbuffer.height],
                        reference: gfile,
                    });
                }
                Some(r)
            }
        };
        let camera = match &self.camera {
            None => None,
            Some(t) => {
                let cfile = t.resolve(&self.dir, frame);
                let mut c = Camera::read(&cfile, frame)?;
                // A supersampled G-buffer holds `supersample` samples per camera pixel
                // along each axis; the frame is shaded at that resolution.
                let n = self.supersample;
                let res = [c.resolution[0] as usize * n, c.resolution[1] as usize * n];
                if res != [gbuffer.width, gbuffer.height] {
                    return Err(SceneError::SizeMismatch {
                        file: cfile,
                        found: res,
                        expected: [gbuffer.width, gbuffer.height],
                        reference: gfile,
                    });
                }
                c.resolution = [res[0] as u32, res[1] as u32];
                Some(c)
            }
        };
        let FrameBlockers { spheres: blockers, sun_shadows } = match &self.blockers {
            None => FrameBlockers::default(),
            Some(t) => camera::read_blockers(&t.resolve(&self.dir, frame), frame, &self.dir)?,
        };
        // The frame's file read once, for the height map, the light and the lamps.
        let changes = self.changes(frame)?;
        let height_map = self.height_map_within(frame, changes.rectangle)?;
        let (light, light_file_crc) = self.light_changed(frame, changes.light.as_ref())?;
        let (suns, points) = match changes.lamps {
            Some((suns, points)) => (suns.iter().map(|sun| sun.turned(self.light_turn)).collect(), points),
            None => (self.suns.clone(), self.points.clone()),
        };
        Ok(OpenFrame {
            number: frame,
            gbuffer,
            reflection,
            camera,
            blockers,
            sun_shadows,
            height_map,
            light,
            light_file_crc,
            suns,
            points,
        })
    }
}
