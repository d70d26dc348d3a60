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

pub mod builtin;

/// A GGX microfacet material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// The material's name (for messages).
    #[serde(default)]
    pub name: String,
    /// GGX roughness α (the squared perceptual roughness \[Karis13\]), in (0, 1].
    #[serde(default = "default_roughness")]
    pub roughness: f32,
    /// Diffuse (Lambertian) albedo, linear RGB in [0, 1].
    #[serde(default = "default_albedo")]
    pub albedo: [f32; 3],
    /// Specular colour F0 (Fresnel at normal incidence), linear RGB in [0, 1].
    #[serde(default = "default_specular")]
    pub specular: [f32; 3],
}

fn default_roughness() -> f32 {
    0.3
}
fn default_albedo() -> [f32; 3] {
    [0.6, 0.6, 0.6]
}
fn default_specular() -> [f32; 3] {
    [0.04, 0.04, 0.04]
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            roughness: default_roughness(),
            albedo: default_albedo(),
            specular: default_specular(),
        }
    }
}

/// A planar convex polygonal light of uniform (or textured) radiance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolygonLight {
    /// 3 to 8 coplanar vertices of a convex polygon, counter-clockwise seen from the emitting
    /// side (the emitting normal is `(v1 - v0) × (v2 - v0)`).
    pub vertices: Vec<[f32; 3]>,
    /// Emitted radiance, linear RGB (W·sr⁻¹·m⁻²).
    pub radiance: [f32; 3],
    /// Emits from both sides.
    #[serde(default)]
    pub two_sided: bool,
    /// Optional texture (path relative to the scene file) modulating the radiance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<String>,
    /// Optional box the light stays inside while it moves. Directions from a vertex that cannot
    /// reach this box can never see the light, so the bake treats them as "don't care".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<Region>,
}

/// An axis-aligned region of space, as written in scene files.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Smallest corner.
    pub min: [f32; 3],
    /// Largest corner.
    pub max: [f32; 3],
}

impl Region {
    /// The region as a box.
    pub fn aabb(&self) -> Aabb {
        Aabb {
            min: Vec3::from(self.min),
            max: Vec3::from(self.max),
        }
    }
}

/// A pinhole camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Eye position.
    pub position: [f32; 3],
    /// The point looked at.
    pub target: [f32; 3],
    /// Up direction (default +Y).
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view in degrees.
    #[serde(default = "default_fov")]
    pub fov_y_deg: f32,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f32 {
    40.0
}

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
        Ok(())
    }
}

/// What a scene file says about its geometry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshRef {
    /// Path relative to the scene file, or `builtin:NAME` for a procedural scene mesh.
    pub path: String,
    /// Material index (into the scene file's `materials`) for the whole mesh. Without it, the
    /// file's own materials are used (glTF, OBJ/MTL; appended after the scene file's), or
    /// material 0 when the file has none.
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
    /// Also light the scene with the mesh files' own lamps (emissive materials); default true.
    #[serde(default = "default_true")]
    pub asset_lights: bool,
    /// Without a camera, the first mesh file's camera is used, else the scene is framed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<Camera>,
    /// Settings of the visibility bake.
    #[serde(default)]
    pub bake: BakeSettings,
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
    /// The polygonal lights.
    pub lights: Vec<PolygonLight>,
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

impl PolygonLight {
    /// The light's corners as vectors.
    pub fn points(&self) -> Vec<Vec3> {
        self.vertices.iter().map(|&v| Vec3::from(v)).collect()
    }

    /// Unit normal of the emitting side.
    pub fn normal(&self) -> Vec3 {
        let p = self.points();
        newell_normal(&p).normalize_or_zero()
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("lights[{index}]: {m}")));
        let n = self.vertices.len();
        if !(3..=8).contains(&n) {
            return bad(format!("has {n} vertices; a light needs 3 to 8"));
        }
        if self.vertices.iter().flatten().any(|x| !x.is_finite()) {
            return bad("a vertex is NaN or infinite".into());
        }
        if self.radiance.iter().any(|x| !x.is_finite() || *x < 0.0) {
            return bad("radiance must be finite and ≥ 0".into());
        }
        let p = self.points();
        let normal = newell_normal(&p);
        let size = Aabb::from_points(&p).diagonal();
        let area2 = normal.length();
        if area2.is_nan() || area2 <= 1e-12 * size * size {
            return bad("polygon has zero area".into());
        }
        let nrm = normal / area2;
        // Planarity: every vertex within 1e-3 of the polygon's size from its plane.
        let d0 = nrm.dot(p[0]);
        if p.iter().any(|q| (nrm.dot(*q) - d0).abs() > 1e-3 * size) {
            return bad("vertices are not coplanar".into());
        }
        // Convexity: every turn has the same sign as the polygon normal.
        for i in 0..n {
            let (a, b, c) = (p[i], p[(i + 1) % n], p[(i + 2) % n]);
            if (b - a).cross(c - b).dot(nrm) < -1e-6 * size * size {
                return bad(format!(
                    "polygon is not convex (or not counter-clockwise) at vertex {}",
                    (i + 1) % n
                ));
            }
        }
        if let Some(r) = &self.region {
            let b = r.aabb();
            if !b.is_valid() {
                return bad("region min must be ≤ max and finite".into());
            }
            let eps = 1e-4 * size.max(b.diagonal());
            if p.iter().any(|q| {
                q.cmplt(b.min - Vec3::splat(eps)).any() || q.cmpgt(b.max + Vec3::splat(eps)).any()
            }) {
                return bad("the light starts outside its declared region".into());
            }
        }
        Ok(())
    }
}

/// Newell's polygon normal: robust for any planar polygon, length = 2 · area.
pub(crate) fn newell_normal(p: &[Vec3]) -> Vec3 {
    let mut n = Vec3::ZERO;
    for i in 0..p.len() {
        n += p[i].cross(p[(i + 1) % p.len()]);
    }
    n
}

impl Material {
    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let bad = |m: String| Err(SceneError::Invalid(format!("materials[{index}]: {m}")));
        if !(self.roughness.is_finite() && self.roughness > 0.0 && self.roughness <= 1.0) {
            return bad(format!("roughness {} must be in (0, 1]", self.roughness));
        }
        let unit = |c: &[f32; 3]| c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x));
        if !unit(&self.albedo) {
            return bad("albedo must be in [0, 1]".into());
        }
        if !unit(&self.specular) {
            return bad("specular must be in [0, 1]".into());
        }
        Ok(())
    }
}

impl Camera {
    /// A camera looking at `bounds` from the front-right and above, fitting its bounding sphere.
    pub(crate) fn framing(bounds: &Aabb) -> Camera {
        let center = bounds.center();
        let radius = (0.5 * bounds.diagonal()).max(1e-6);
        let fov_y_deg = default_fov();
        let dist = radius / (0.5 * fov_y_deg.to_radians()).sin() * 1.05;
        let dir = Vec3::new(0.55, 0.45, 1.0).normalize();
        Camera {
            position: (center + dir * dist).to_array(),
            target: center.to_array(),
            up: default_up(),
            fov_y_deg,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), SceneError> {
        let p = Vec3::from(self.position);
        let t = Vec3::from(self.target);
        let up = Vec3::from(self.up);
        if !(p.is_finite() && t.is_finite() && up.is_finite()) {
            return Err(SceneError::Invalid(
                "camera has a NaN or infinite value".into(),
            ));
        }
        let f = t - p;
        if f.length_squared() == 0.0 || f.cross(up).length_squared() == 0.0 {
            return Err(SceneError::Invalid(
                "camera target equals its position or looks along `up`".into(),
            ));
        }
        if !(self.fov_y_deg > 0.1 && self.fov_y_deg < 179.0) {
            return Err(SceneError::Invalid(format!(
                "camera fov_y_deg {} is outside (0.1, 179)",
                self.fov_y_deg
            )));
        }
        Ok(())
    }
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
        if self.lights.is_empty() {
            return Err(SceneError::Invalid("scene has no lights".into()));
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.validate(i)?;
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

    /// The union of the declared light regions, or `None` when any light may go anywhere.
    pub fn light_region(&self) -> Option<Vec<Aabb>> {
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
        let mut asset_camera = None;
        let mut materials = std::mem::take(&mut file.materials);
        for (i, (m, asset)) in file.meshes.iter().zip(parts).enumerate() {
            let Asset {
                mesh: mut part,
                materials: own,
                lights: lamps,
                camera,
                warnings: w,
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
            } else if !lamps.is_empty() {
                warnings.push(format!(
                    "{}: its {} lamps are not used (asset_lights is false)",
                    m.path,
                    lamps.len()
                ));
            }
            if asset_camera.is_none() && affine.is_none() {
                asset_camera = camera;
            }
            // The entry's material for the whole mesh, else the file's own materials.
            let offset = match m.material {
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
        if file.ground_plane {
            let ground = builtin::ground_under(&model, file.ground_material);
            mesh.append(&ground, 0);
        }
        let camera = file
            .camera
            .or(asset_camera)
            .unwrap_or_else(|| Camera::framing(&model));
        if materials.is_empty() {
            materials = default_materials();
        }
        let mut scene = Scene {
            mesh,
            materials,
            lights,
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
            camera: self.camera.clone(),
            bake: self.bake.clone(),
            motion: Vec::new(),
            warnings: self.warnings.clone(),
        };
        self.pose_into(t, &mut s.mesh);
        s
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
    /// With lamps (emissive materials) the asset is the whole scene: its lamps, its materials,
    /// its camera or one framing it, no ground. Without, it gets a tessellated ground plane
    /// under it and a quad light above it, and a warning says so. Without materials of its
    /// own, it gets a grey GGX (and the ground a slightly rougher grey).
    pub fn from_asset(asset: Asset) -> Result<Scene, SceneError> {
        let Asset {
            mut mesh,
            materials,
            lights,
            camera,
            mut warnings,
        } = asset;
        mesh.validate()?;
        let bounds = mesh.bounds();
        let mut materials = if materials.is_empty() {
            mesh.material_ids.iter_mut().for_each(|m| *m = 0);
            vec![Material {
                name: "model".into(),
                ..Material::default()
            }]
        } else {
            materials
        };
        let lights = if lights.is_empty() {
            let ground_id = materials.len() as u32;
            materials.push(Material {
                name: "ground".into(),
                roughness: 0.5,
                albedo: [0.5, 0.5, 0.5],
                specular: [0.04; 3],
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
            lights
        };
        let scene = Scene {
            camera: camera.unwrap_or_else(|| Camera::framing(&bounds)),
            mesh,
            materials,
            lights,
            bake: BakeSettings::default(),
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
