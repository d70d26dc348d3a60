//! The scene model and its JSON file format (documented in `docs/scene-format.md`).
//!
//! Conventions follow glTF: right-handed, +Y up, metres. A [`SceneFile`] is what a user writes;
//! [`Scene`] is the same with the mesh loaded and everything validated.

use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::import::Asset;
use crate::mesh::{Aabb, Mesh};
use crate::motion::{Motion, MovingPart, Transform};
use crate::texture::LightImage;

pub mod builtin;

pub use crate::camera::Camera;
pub use crate::environment::Environment;
pub use crate::light::{
    DEFAULT_SPHERE_RADIUS, LightMotion, PolygonLight, PunctualLight, Region, SUN_ANGULAR_DIAMETER,
    Spot, SunLight,
};
pub use crate::material::{Cutout, Material, MaterialMaps, NormalMap};

/// How the BSPVT builder chooses a split line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplitMethod {
    /// Exact line search over the quantised offsets for a coarse-to-fine set of angles.
    #[default]
    Default,
    /// Exact line search over every quantised angle and offset (slow; the quality reference).
    Exhaustive,
    /// The paper's Nelder–Mead minimisation of E(P, l) [paper000 §3.2 eq. 3] \[Nelder65\] (the
    /// baseline).
    NelderMead,
}

/// Settings of the visibility bake.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BakeSettings {
    /// Cube-map face resolution in pixels (per side).
    #[serde(default = "default_face_res")]
    pub face_res: u32,
    /// Leaf tolerance ε [paper000 §3.2]: a node is a leaf when Σ (V − v̄)² over its pixels is at
    /// most `epsilon · face_res²`, i.e. ε is a fraction of the face's pixel count.
    #[serde(default = "default_epsilon")]
    pub epsilon: f32,
    /// Rays per pixel side: `s` casts s×s rays per pixel and stores fractional visibility.
    #[serde(default = "default_supersampling")]
    pub supersampling: u32,
    /// How the builder chooses split lines.
    #[serde(default)]
    pub split: SplitMethod,
    /// Vertices per stored chunk.
    #[serde(default = "default_chunk_vertices")]
    pub chunk_vertices: u32,
    /// Adaptive refinement of the mesh before the bake where the lights' visibility varies
    /// across a triangle (docs/bake.md "Refinement"); `None`: the mesh is baked as given.
    #[serde(default)]
    pub refine: Option<Refinement>,
}

/// How finely the bake refines a mesh where shadows cross its triangles: a triangle is split
/// (conforming longest-edge bisection) while the visibility of the lights, sampled at its
/// vertices and edge midpoints, varies by more than `tolerance` across it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Refinement {
    /// Largest allowed variation of the visibility V ∈ [0, 1] (the fraction of the light's
    /// samples seen) across a triangle. Finite, ≥ 0 (≥ 1 never splits).
    #[serde(default = "default_tolerance")]
    pub tolerance: f32,
    /// Largest allowed variation of the lights' unshadowed irradiance across a triangle, as a
    /// fraction of its largest value there: what per-vertex shading must interpolate besides
    /// the shadows. Lights with a region (moving lights) do not count, nor surfaces lit below
    /// 10⁻³ of the brightest vertex. Finite, ≥ 0; 0: visibility alone decides.
    #[serde(default = "default_lighting")]
    pub lighting: f32,
    /// Shortest edge that may still be split, in scene units; 0: the scene's diagonal / 256.
    #[serde(default)]
    pub min_edge: f32,
    /// Vertex budget of the refined mesh (the original vertices included).
    #[serde(default = "default_max_vertices")]
    pub max_vertices: u32,
}

fn default_tolerance() -> f32 {
    0.1
}
fn default_lighting() -> f32 {
    0.25
}
fn default_max_vertices() -> u32 {
    200_000
}

impl Default for Refinement {
    /// Tolerances 0.1 (visibility) and 0.25 (lighting), shortest edge the diagonal / 256, at most
    /// 200,000 vertices.
    fn default() -> Self {
        Refinement {
            tolerance: default_tolerance(),
            lighting: default_lighting(),
            min_edge: 0.0,
            max_vertices: default_max_vertices(),
        }
    }
}

impl Refinement {
    /// Largest vertex budget a scene may ask for.
    pub const MAX_VERTICES: u32 = 20_000_000;

    /// Checks every field; the message names the field and what it may be.
    pub fn validate(&self) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("bake.refine.{m}")));
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return bad(format!(
                "tolerance = {} must be a finite fraction ≥ 0 (e.g. 0.1)",
                self.tolerance
            ));
        }
        if !(self.lighting.is_finite() && self.lighting >= 0.0) {
            return bad(format!(
                "lighting = {} must be a finite fraction ≥ 0 (e.g. 0.1; 0: off)",
                self.lighting
            ));
        }
        if !(self.min_edge.is_finite() && self.min_edge >= 0.0) {
            return bad(format!(
                "min_edge = {} must be a finite length ≥ 0 in scene units (0: the scene's \
                 diagonal / 256)",
                self.min_edge
            ));
        }
        if self.max_vertices > Self::MAX_VERTICES {
            return bad(format!(
                "max_vertices = {} is above {}",
                self.max_vertices,
                Self::MAX_VERTICES
            ));
        }
        Ok(())
    }
}

fn default_face_res() -> u32 {
    64
}
fn default_epsilon() -> f32 {
    1e-3
}
fn default_supersampling() -> u32 {
    1
}
fn default_chunk_vertices() -> u32 {
    1024
}

impl Default for BakeSettings {
    fn default() -> Self {
        BakeSettings {
            face_res: default_face_res(),
            epsilon: default_epsilon(),
            supersampling: default_supersampling(),
            split: SplitMethod::Default,
            chunk_vertices: default_chunk_vertices(),
            refine: None,
        }
    }
}

impl BakeSettings {
    /// Largest face resolution a scene may ask for.
    pub const MAX_FACE_RES: u32 = 512;
    /// Largest supersampling a scene may ask for.
    pub const MAX_SUPERSAMPLING: u32 = 8;
    /// Largest chunk a scene may ask for, in vertices.
    pub const MAX_CHUNK_VERTICES: u32 = 65_536;

    pub(crate) fn validate(&self) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(m));
        if !(4..=Self::MAX_FACE_RES).contains(&self.face_res) {
            return bad(format!(
                "bake.face_res = {} is outside 4..={}",
                self.face_res,
                Self::MAX_FACE_RES
            ));
        }
        if !(self.epsilon.is_finite() && self.epsilon >= 0.0) {
            return bad(format!(
                "bake.epsilon = {} must be finite and ≥ 0",
                self.epsilon
            ));
        }
        if !(1..=Self::MAX_SUPERSAMPLING).contains(&self.supersampling) {
            return bad(format!(
                "bake.supersampling = {} is outside 1..={}",
                self.supersampling,
                Self::MAX_SUPERSAMPLING
            ));
        }
        if !(1..=Self::MAX_CHUNK_VERTICES).contains(&self.chunk_vertices) {
            return bad(format!(
                "bake.chunk_vertices = {} is outside 1..={}",
                self.chunk_vertices,
                Self::MAX_CHUNK_VERTICES
            ));
        }
        match &self.refine {
            Some(r) => r.validate(),
            None => Ok(()),
        }
    }
}

/// What a scene file says about its geometry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshRef {
    /// Path relative to the scene file, or `builtin:NAME` for a procedural scene mesh.
    pub path: String,
    /// Material index (into the scene file's `materials`) for the whole mesh (for a file
    /// without materials of its own, such as a built-in mesh of several parts, it shifts the
    /// mesh's ids). Without it, the file's own materials are used (glTF, OBJ/MTL; appended
    /// after the scene file's), or material 0 when the file has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<u32>,
    /// Where the mesh sits (default: as in its file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transform: Option<Transform>,
    /// How the mesh moves over the animation cycle (run-time methods only; see
    /// [`crate::motion`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<Motion>,
}

/// A scene file as written by a user (JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// One or more meshes, concatenated in order (vertex order = tree order).
    pub meshes: Vec<MeshRef>,
    /// Adds a tessellated ground plane under the meshes (material index `ground_material`).
    #[serde(default)]
    pub ground_plane: bool,
    /// Material index of the ground plane.
    #[serde(default)]
    pub ground_material: u32,
    /// The materials (default: one).
    #[serde(default = "default_materials")]
    pub materials: Vec<Material>,
    /// The polygonal lights (added to the lamps of the mesh files, see `asset_lights`).
    #[serde(default)]
    pub lights: Vec<PolygonLight>,
    /// Point and spot lights (added to the mesh files' `KHR_lights_punctual` ones).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub punctual: Vec<PunctualLight>,
    /// Directional lights, the sun (added to the mesh files' own).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub suns: Vec<SunLight>,
    /// The sphere radius of the point and spot lights that do not give one (default
    /// [`DEFAULT_SPHERE_RADIUS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub punctual_radius: Option<f32>,
    /// Also light the scene with the mesh files' own lamps (emissive materials) and
    /// `KHR_lights_punctual` lights; default true.
    #[serde(default = "default_true")]
    pub asset_lights: bool,
    /// Without a camera, the first mesh file's camera is used, else the scene is framed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<Camera>,
    /// Settings of the visibility bake.
    #[serde(default)]
    pub bake: BakeSettings,
    /// Light from an environment map at infinity (the sky), besides or instead of the
    /// polygonal lights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<Environment>,
}

fn default_true() -> bool {
    true
}

fn default_materials() -> Vec<Material> {
    vec![Material::default()]
}

/// A loaded, validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The meshes and the ground, concatenated (vertex order = tree order).
    pub mesh: Mesh,
    /// The materials, indexed by the mesh's material ids.
    pub materials: Vec<Material>,
    /// The polygonal lights (none: a scene lit by its environment alone).
    pub lights: Vec<PolygonLight>,
    /// Point and spot lights (`KHR_lights_punctual`): points for the point-light methods,
    /// small spheres for the others.
    pub punctual: Vec<PunctualLight>,
    /// Directional lights: disks at infinity (the sun).
    pub suns: Vec<SunLight>,
    /// The environment light, its path resolved (not part of the bake's identity: the
    /// service does not store it).
    pub environment: Option<Environment>,
    /// The camera (given or framed).
    pub camera: Camera,
    /// Settings of the visibility bake.
    pub bake: BakeSettings,
    /// The meshes that move (empty: a static scene). `mesh` is the pose at t = 0.
    pub motion: Vec<MovingPart>,
    /// What the loader did not use or added on its own (ignored textures, a default light),
    /// one sentence each, for the front ends to show. Not part of the scene's identity.
    pub warnings: Vec<String>,
}

impl Scene {
    /// Checks every part of the scene; loaders call this before returning.
    pub fn validate(&self) -> Result<(), SceneError> {
        self.mesh.validate()?;
        if self.materials.is_empty() {
            return Err(SceneError::Invalid("scene has no materials".into()));
        }
        for (i, m) in self.materials.iter().enumerate() {
            m.validate(i)?;
        }
        if let Some(&m) = self
            .mesh
            .material_ids
            .iter()
            .find(|&&m| m as usize >= self.materials.len())
        {
            return Err(SceneError::Invalid(format!(
                "material index {m} used, but the scene has {} materials",
                self.materials.len()
            )));
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.validate(i)?;
        }
        for (i, l) in self.punctual.iter().enumerate() {
            l.validate(i)?;
        }
        for (i, l) in self.suns.iter().enumerate() {
            l.validate(i)?;
        }
        if let Some(e) = &self.environment {
            e.validate()?;
        }
        self.camera.validate()?;
        for (i, part) in self.motion.iter().enumerate() {
            part.validate(i, self.mesh.vertex_count(), self.mesh.triangles.len())?;
        }
        self.bake.validate()
    }

    /// The lights that light nothing where they rest: one-sided lights with every vertex of the
    /// mesh behind or in their plane (typically a polygon wound the wrong way round). A render
    /// with such a light is black; the front ends say so instead of drawing it silently.
    pub fn lights_facing_away(&self) -> Vec<usize> {
        self.lights
            .iter()
            .enumerate()
            .filter(|(_, l)| {
                let n = l.normal();
                let p = l.points();
                let c = p.iter().copied().sum::<Vec3>() / p.len().max(1) as f32;
                !l.two_sided
                    && n != Vec3::ZERO
                    && !self.mesh.positions.iter().any(|&v| (v - c).dot(n) > 0.0)
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The union of the declared light regions, or `None` when any light may go anywhere —
    /// and for a scene without lights, whose bake is the sky's: every direction matters.
    pub fn light_region(&self) -> Option<Vec<Aabb>> {
        if self.lights.is_empty() {
            return None;
        }
        self.lights
            .iter()
            .map(|l| l.region.map(|r| r.aabb()))
            .collect()
    }

    /// Parses a scene file's text; `base_dir` resolves relative mesh paths.
    pub fn from_json(text: &str, base_dir: &Path) -> Result<Scene, SceneError> {
        let file: SceneFile = serde_json::from_str(text)?;
        Scene::from_file(file, base_dir)
    }

    /// Loads a scene file from disk.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Scene::from_json(&text, &base)
    }

    /// Resolves and loads the meshes a scene file names, then validates the result.
    pub(crate) fn from_file(file: SceneFile, base_dir: &Path) -> Result<Scene, SceneError> {
        let parts = file
            .meshes
            .iter()
            .map(|m| match m.path.strip_prefix("builtin:") {
                Some(name) => builtin::mesh(name)
                    .map(|mesh| Asset {
                        mesh,
                        ..Asset::default()
                    })
                    .ok_or_else(|| {
                        SceneError::Invalid(format!(
                            "unknown built-in mesh {name:?} (known: {})",
                            builtin::mesh_names().join(", ")
                        ))
                    }),
                None => Ok(crate::import::load_asset(&base_dir.join(&m.path))?),
            })
            .collect::<Result<Vec<Asset>, SceneError>>()?;
        let mut file = file;
        if let Some(e) = &mut file.environment {
            e.path = base_dir.join(&e.path).to_string_lossy().into_owned();
        }
        file.load_light_textures(|path| {
            let path = base_dir.join(path);
            let len = std::fs::metadata(&path).map_err(|e| e.to_string())?.len();
            if len > MAX_LIGHT_TEXTURE_FILE_BYTES {
                return Err(format!("{len} bytes is over the limit"));
            }
            std::fs::read(&path)
                .map(std::borrow::Cow::Owned)
                .map_err(|e| e.to_string())
        })?;
        Scene::assemble(file, parts)
    }

    /// A scene from its file and the assets it names (`parts`, in the order of
    /// `file.meshes`): each mesh placed by its transform with its materials (the entry's, or
    /// the file's own appended after the scene file's, a scene-file material of the same name
    /// replacing an asset's), its lamps added (placed by the same transform), the moving ones
    /// recorded, the ground plane added, the camera taken or framed, the whole posed at t = 0
    /// and validated. Every loader (files here, uploads in the server) goes through this.
    pub fn assemble(mut file: SceneFile, parts: Vec<Asset>) -> Result<Scene, SceneError> {
        if file.meshes.is_empty() {
            return Err(SceneError::Invalid("scene names no meshes".into()));
        }
        if parts.len() != file.meshes.len() {
            return Err(SceneError::Invalid(format!(
                "{} meshes for {} mesh entries",
                parts.len(),
                file.meshes.len()
            )));
        }
        let mut mesh = Mesh::default();
        let mut motion = Vec::new();
        let mut warnings = Vec::new();
        let mut lights = std::mem::take(&mut file.lights);
        let mut punctual = std::mem::take(&mut file.punctual);
        let mut suns = std::mem::take(&mut file.suns);
        let mut asset_camera = None;
        let mut materials = std::mem::take(&mut file.materials);
        for (i, (m, asset)) in file.meshes.iter().zip(parts).enumerate() {
            let Asset {
                mesh: mut part,
                materials: own,
                lights: lamps,
                punctual: points,
                suns: asset_suns,
                camera,
                warnings: w,
                files: _,
            } = asset;
            warnings.extend(w.into_iter().map(|w| format!("{}: {w}", m.path)));
            let affine = match &m.transform {
                Some(t) => {
                    t.validate_entry(i)?;
                    let a = t.affine(glam::Vec3::ZERO);
                    part.transform(&a);
                    Some(a)
                }
                None => None,
            };
            let place = |p: [f32; 3]| match &affine {
                Some(a) => a.transform_point3(Vec3::from(p)).to_array(),
                None => p,
            };
            if file.asset_lights {
                for mut l in lamps {
                    l.vertices = l.vertices.iter().map(|&v| place(v)).collect();
                    lights.push(l);
                }
                for mut l in points {
                    l.position = place(l.position);
                    if let (Some(s), Some(a)) = (&mut l.spot, &affine) {
                        s.direction = a
                            .transform_vector3(Vec3::from(s.direction))
                            .normalize_or_zero()
                            .to_array();
                    }
                    punctual.push(l);
                }
                for mut l in asset_suns {
                    if let Some(a) = &affine {
                        l.direction = a
                            .transform_vector3(Vec3::from(l.direction))
                            .normalize_or_zero()
                            .to_array();
                    }
                    suns.push(l);
                }
            } else if !lamps.is_empty() || !points.is_empty() || !asset_suns.is_empty() {
                warnings.push(format!(
                    "{}: its {} lamps and {} punctual lights are not used (asset_lights is \
                     false)",
                    m.path,
                    lamps.len(),
                    points.len() + asset_suns.len()
                ));
            }
            if asset_camera.is_none() && affine.is_none() {
                asset_camera = camera;
            }
            // The entry's material for the whole mesh, else the file's own materials.
            let offset = match m.material {
                // A file without materials (PLY, a built-in part): its ids shifted by the
                // entry's (all 0 for a plain mesh, so the entry's material throughout).
                Some(id) if own.is_empty() => id,
                // A file with its own materials: the entry's replaces them all.
                Some(id) => {
                    part.material_ids.iter_mut().for_each(|x| *x = id);
                    0
                }
                None if own.is_empty() => 0,
                None => {
                    let mut remap = Vec::with_capacity(own.len());
                    for o in own {
                        // A scene-file material of the same name overrides the asset's.
                        match materials
                            .iter()
                            .position(|f| !o.name.is_empty() && f.name == o.name)
                        {
                            Some(j) => remap.push(j as u32),
                            None => {
                                remap.push(materials.len() as u32);
                                materials.push(o);
                            }
                        }
                    }
                    part.material_ids
                        .iter_mut()
                        .for_each(|x| *x = remap.get(*x as usize).copied().unwrap_or(0));
                    0
                }
            };
            if let Some(mo) = &m.motion {
                mo.validate(i)?;
                motion.push(MovingPart::new(
                    mesh.positions.len() as u32,
                    mesh.triangles.len() as u32,
                    part.triangles.len() as u32,
                    &part.positions,
                    &part.normals,
                    mo.clone(),
                ));
            }
            mesh.append(&part, offset);
        }
        let model = mesh.bounds();
        let model_mesh = if file.camera.is_none() && asset_camera.is_none() {
            mesh.clone()
        } else {
            Mesh::default()
        };
        if file.ground_plane {
            let ground = builtin::ground_under(&model, file.ground_material);
            mesh.append(&ground, 0);
        }
        let camera = file
            .camera
            .or(asset_camera)
            .unwrap_or_else(|| Camera::framing_mesh(&model_mesh));
        if materials.is_empty() {
            materials = default_materials();
        }
        if let Some(r) = file.punctual_radius {
            if !(r > 0.0 && r.is_finite()) {
                return Err(SceneError::Invalid(
                    "punctual_radius must be finite and > 0".into(),
                ));
            }
            for l in punctual.iter_mut().filter(|l| l.radius.is_none()) {
                l.radius = Some(r);
            }
        }
        let mut scene = Scene {
            mesh,
            materials,
            lights,
            punctual,
            suns,
            environment: file.environment,
            camera,
            bake: file.bake,
            motion,
            warnings,
        };
        let mut at0 = std::mem::take(&mut scene.mesh);
        scene.pose_into(0.0, &mut at0);
        scene.mesh = at0;
        scene.validate()?;
        Ok(scene)
    }

    /// The scene whose bake is the visibility of the sky: the same mesh (as given: no further
    /// refinement) without its polygonal lights, so every direction above a vertex's horizon
    /// matters and every ray runs to infinity. Environment lighting through the trees
    /// (`bspvt-env`) shades with this bake; the lamps keep theirs, whose rays end at the lamp.
    /// The suns stay (they stop no ray): the bake aims at each one at rest
    /// (`bspvt_bake::SunDisk`), so they are part of its identity (a cache's key).
    pub fn sky(&self) -> Scene {
        let mut s = self.clone();
        s.lights.clear();
        s.punctual.clear();
        s.bake.refine = None;
        s.warnings.clear();
        s
    }

    /// Whether the suns are shaded through the sky's bake ([`Scene::sky`]): when the scene also
    /// has lamps or point and spot lights, whose bake ends rays at them (a sun may turn to any
    /// direction, rays to infinity; docs/bake.md). A scene lit by suns alone bakes the sky's
    /// visibility as its own.
    pub fn suns_in_sky_bake(&self) -> bool {
        !self.suns.is_empty() && (!self.lights.is_empty() || !self.punctual.is_empty())
    }

    /// True when some mesh moves.
    pub fn is_dynamic(&self) -> bool {
        !self.motion.is_empty()
    }

    /// Poses the moving meshes at cycle time `t` into `mesh`, a copy of [`Scene::mesh`] (the
    /// static parts are left as they are).
    pub fn pose_into(&self, t: f32, mesh: &mut Mesh) {
        for part in &self.motion {
            part.pose_into(t, &mut mesh.positions, &mut mesh.normals, &mesh.triangles);
        }
    }

    /// The scene frozen at cycle time `t`: a static copy (no motion) posed at `t`.
    pub fn at(&self, t: f32) -> Scene {
        let mut s = Scene {
            mesh: self.mesh.clone(),
            materials: self.materials.clone(),
            lights: self.lights.clone(),
            punctual: self.punctual.clone(),
            suns: self.suns.clone(),
            environment: self.environment.clone(),
            camera: self.camera.clone(),
            bake: self.bake.clone(),
            motion: Vec::new(),
            warnings: self.warnings.clone(),
        };
        self.pose_into(t, &mut s.mesh);
        s
    }

    /// Whether [`Scene::from_asset`] puts a ground plane and a quad light around `asset`: it
    /// brings no light of its own, neither lamps nor punctual lights.
    pub fn adds_ground(asset: &Asset) -> bool {
        asset.lights.is_empty() && asset.punctual.is_empty() && asset.suns.is_empty()
    }

    /// The default scene for a bare mesh (an asset without lamps, materials or camera).
    pub fn from_mesh(mesh: Mesh) -> Result<Scene, SceneError> {
        Scene::from_asset(Asset {
            mesh,
            ..Asset::default()
        })
    }

    /// The scene of an asset given alone (`--mesh`, or an upload without a scene file).
    ///
    /// With lamps (emissive materials) or punctual lights the asset is the whole scene: its
    /// lights, its materials, its camera or one framing it, no ground. Without, it gets a tessellated ground plane
    /// under it and a quad light above it, and a warning says so. Without materials of its
    /// own, it gets a grey GGX (and the ground a slightly rougher grey).
    pub fn from_asset(asset: Asset) -> Result<Scene, SceneError> {
        let adds_ground = Scene::adds_ground(&asset);
        let Asset {
            mut mesh,
            materials,
            lights,
            punctual,
            suns,
            camera,
            mut warnings,
            files: _,
        } = asset;
        mesh.validate()?;
        let bounds = mesh.bounds();
        // Framed on the model, before a ground is added.
        let camera = camera.unwrap_or_else(|| Camera::framing_mesh(&mesh));
        let mut materials = if materials.is_empty() {
            mesh.material_ids.iter_mut().for_each(|m| *m = 0);
            vec![Material {
                name: "model".into(),
                ..Material::default()
            }]
        } else {
            materials
        };
        let mut bake = BakeSettings::default();
        let lights = if adds_ground {
            let ground_id = materials.len() as u32;
            materials.push(Material {
                name: "ground".into(),
                roughness: 0.5,
                albedo: [0.5, 0.5, 0.5],
                specular: [0.04; 3],
                maps: None,
                cutout: None,
                normal_map: None,
            });
            mesh.append(&builtin::ground_under(&bounds, ground_id), 0);
            let light = builtin::quad_light_above(&bounds, [8.0, 8.0, 8.0]);
            warnings.push(
                "the mesh has no lamp (no emissive material): a quad light above it and a \
                 ground plane under it were added"
                    .into(),
            );
            vec![light]
        } else {
            // The asset's own scene (a room, a lamp over a table, lit by lamps, points,
            // spots or a sun): its large flat polygons need refining where shadows cross them.
            bake.refine = Some(Refinement::default());
            lights
        };
        let scene = Scene {
            camera,
            mesh,
            materials,
            lights,
            punctual,
            suns,
            environment: None,
            bake,
            motion: Vec::new(),
            warnings,
        };
        scene.validate()?;
        Ok(scene)
    }

    /// Loads `path` as an asset given alone ([`Scene::from_asset`]).
    pub fn from_mesh_path(path: &Path) -> Result<Scene, SceneError> {
        Scene::from_asset(crate::import::load_asset(path)?)
    }
}

/// Largest light texture file read (an 8-bit PNG of the largest allowed texture is far below).
pub const MAX_LIGHT_TEXTURE_FILE_BYTES: u64 = 256 << 20;

impl SceneFile {
    /// Decodes the `texture` of each light that names one into its `image`, reading the file
    /// through `read` (a path relative to the scene file: from disk beside it, or from an
    /// upload's files), so the scene carries the texels wherever it goes (a service's stored
    /// scene, every client). A texture that cannot be read or decoded is an error naming the
    /// light.
    pub fn load_light_textures<'f>(
        &mut self,
        read: impl Fn(&str) -> Result<std::borrow::Cow<'f, [u8]>, String>,
    ) -> Result<(), SceneError> {
        for (i, l) in self.lights.iter_mut().enumerate() {
            if let (Some(path), None) = (&l.texture, &l.image) {
                let image = read(path)
                    .and_then(|bytes| LightImage::decode(&bytes))
                    .map_err(|e| {
                        SceneError::Invalid(format!("light {i}: texture {path:?}: {e}"))
                    })?;
                l.image = Some(std::sync::Arc::new(image));
            }
        }
        Ok(())
    }
}

/// Opens the scene a command line names: a scene file, `builtin:NAME`, or a bare mesh
/// (`--mesh PATH`, which gets the default scene of [`Scene::from_mesh`]).
pub fn open_scene(scene: Option<&str>, mesh: Option<&Path>) -> Result<Scene, SceneError> {
    match (scene, mesh) {
        (Some(_), Some(_)) => Err(SceneError::Invalid(
            "give either a scene file or --mesh, not both".into(),
        )),
        (None, Some(m)) => Scene::from_mesh_path(m),
        (Some(s), None) => match s.strip_prefix("builtin:") {
            Some(name) => builtin::scene(name).ok_or_else(|| {
                SceneError::Invalid(format!(
                    "unknown built-in scene {name:?} (known: {})",
                    builtin::NAMES.join(", ")
                ))
            }),
            None => Scene::load(Path::new(s)),
        },
        (None, None) => Err(SceneError::Invalid(
            "no scene: give SCENE.json, builtin:NAME or --mesh PATH".into(),
        )),
    }
}
