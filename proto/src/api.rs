//! The wire types of the baking service's HTTP API, shared by the service and its clients so
//! that a client needs no server code: a scene's [`JobState`] and [`SceneStatus`], the
//! [`ErrorBody`] of every error answer, and the scene as the service stores and serves it
//! ([`encode_scene`], [`decode_scene`]: postcard, version-tagged, exact floats).
//!
//! With the `openapi` feature the types also describe themselves to utoipa.

use serde::{Deserialize, Serialize};

use std::borrow::Cow;
use std::sync::Arc;

use crate::material::{Cutout, MaterialMaps, NormalMap};
use crate::motion::MovingPart;
use crate::scene::{Camera, Material, PolygonLight, PunctualLight, Region, Spot, SunLight};
use crate::texture::{LightImage, Texture, TextureRef, UvTransform, Wrap};
use crate::{BakeSettings, Mesh, Scene};

/// The body of every error answer: `{"error": CODE, "detail": TEXT}`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ErrorBody {
    /// Stable machine-readable code, e.g. `invalid_mesh`, `unauthorized`, `not_found`.
    pub error: String,
    /// What is wrong, in words.
    pub detail: String,
}

/// Where a scene's bake stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Accepted, waiting for a bake slot.
    Queued,
    /// Chunks are being baked.
    Baking,
    /// Every chunk is durable.
    Done,
    /// The bake stopped; `reason` says why.
    Failed,
    /// Deleted by a client; its data is gone.
    Cancelled,
}

impl JobState {
    /// The state's name on the wire and in the database (`queued`, `baking`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Baking => "baking",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state [`JobState::as_str`] names; `None` for any other text.
    pub fn parse(s: &str) -> Option<JobState> {
        Some(match s {
            "queued" => JobState::Queued,
            "baking" => JobState::Baking,
            "done" => JobState::Done,
            "failed" => JobState::Failed,
            "cancelled" => JobState::Cancelled,
            _ => return None,
        })
    }

    /// Whether the state can no longer change by baking.
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
}

/// Where to find a scene's parts.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[allow(
    missing_docs,
    reason = "a doc comment here becomes a description in the served OpenAPI document; `//` comments keep it unchanged"
)]
pub struct Links {
    // The status document (`GET /v1/scenes/{id}`).
    #[serde(rename = "self")]
    pub status: String,
    // The status as server-sent events (`GET /v1/scenes/{id}/events`).
    pub events: String,
    // The mesh as baked (`GET /v1/scenes/{id}/mesh`).
    pub mesh: String,
    /// The scene as baked (`GET /v1/scenes/{id}/scene`).
    #[serde(default)]
    pub scene: String,
    // The encoded trees (`GET /v1/scenes/{id}/trees`).
    pub trees: String,
}

impl Links {
    /// The links of scene `id`.
    pub fn of(id: &str) -> Links {
        Links {
            status: format!("/v1/scenes/{id}"),
            events: format!("/v1/scenes/{id}/events"),
            mesh: format!("/v1/scenes/{id}/mesh"),
            scene: format!("/v1/scenes/{id}/scene"),
            trees: format!("/v1/scenes/{id}/trees"),
        }
    }
}

/// Sizes of a scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[allow(
    missing_docs,
    reason = "a doc comment here becomes a description in the served OpenAPI document; `//` comments keep it unchanged"
)]
pub struct Sizes {
    // Vertices of the mesh as baked (one tree set each).
    pub mesh_vertices: u32,
    // Triangles of the mesh as baked.
    pub mesh_triangles: u64,
    /// Bytes uploaded (mesh file as sent, scene and settings JSON).
    pub upload_bytes: u64,
    /// Bytes of the bake stored so far: header frame + durable chunk frames. When `done`, the
    /// size of the whole tree stream (= the offline bake file).
    pub stored_bytes: u64,
}

/// A scene's status.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[allow(
    missing_docs,
    reason = "a doc comment here becomes a description in the served OpenAPI document; `//` comments keep it unchanged"
)]
pub struct SceneStatus {
    // The scene's id (32 lowercase hex digits).
    pub id: String,
    // Where the bake stands.
    pub state: JobState,
    /// Why the bake failed (`failed`) or stopped (`cancelled`).
    pub reason: Option<String>,
    // Vertices whose trees are durable.
    pub vertices_done: u64,
    // Vertices of the mesh.
    pub vertices_total: u32,
    // Durable chunks.
    pub chunks_done: u32,
    // Chunks of the bake.
    pub chunks_total: u32,
    /// `vertices_done / vertices_total`.
    pub progress: f64,
    /// Vertices per second baked by this server process (while baking).
    pub rate_vertices_per_s: Option<f64>,
    /// Estimated seconds to completion (while baking).
    pub eta_s: Option<f64>,
    /// Scenes ahead of this one (while queued).
    pub queue_position: Option<usize>,
    /// The bake settings (`face_res`, `epsilon`, `supersampling`, `split`, `chunk_vertices`).
    #[cfg_attr(feature = "openapi", schema(value_type = Object))]
    pub settings: serde_json::Value,
    // Sizes of the mesh, the upload and the stored bake.
    pub sizes: Sizes,
    /// The baked mesh's content hash (hex), as in the bake header.
    pub mesh_hash: String,
    /// How the scene was submitted.
    pub source: String,
    /// What the importer did not use (textures, extensions, punctual lights) or added on its
    /// own (a default light and ground), one sentence each.
    #[serde(default)]
    pub warnings: Vec<String>,
    // When the scene was accepted (ms since the Unix epoch).
    pub created_ms: i64,
    // When its bake started (ms since the Unix epoch).
    pub started_ms: Option<i64>,
    // When its bake ended (ms since the Unix epoch).
    pub finished_ms: Option<i64>,
    /// Chunks baked by this server process (a restarted server never re-bakes durable chunks).
    pub chunks_baked_this_process: u32,
    /// Chunks baked over all runs, re-bakes included.
    pub chunks_baked_total: u64,
    /// Stored chunks found corrupt or missing and baked again.
    pub chunks_corrupt: u64,
    // Where to find the scene's parts.
    pub links: Links,
}

// ---------------------------------------------------------------------------------------------
// The scene as stored and served (`GET /v1/scenes/{id}/scene`).

/// 2: adds the moving parts ([`bspvt_proto::motion`]); 3: adds `bake.refine`; 4: adds the
/// camera's `aspect`; 5: adds the mesh's UVs, the materials' textures (each image once, as the
/// PNG or JPEG it came from), the lamps' texture images and the punctual lights; 6 adds which
/// lights move in their plane (before it, every light without a region did; without one now,
/// a lamp is fixed); 7 adds the point and spot lights' sphere radii and the suns; 8 the
/// materials' alpha cut-outs and their textures' UV transforms; 9 their normal maps.
/// Versions 1 to 8 still read.
const STORED_VERSION: u16 = 9;

#[derive(Serialize, Deserialize)]
struct StoredScene<'a> {
    version: u16,
    /// Borrowed when encoding (a big mesh is not copied to be written), owned when read.
    mesh: Cow<'a, Mesh>,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
    /// Empty, or one per vertex.
    uvs: Vec<[f32; 2]>,
    textures: Vec<StoredTexture>,
    /// One per material (or empty: none is textured).
    maps: Vec<Option<StoredMaps>>,
    /// One per light (or empty: none has an image).
    light_images: Vec<Option<StoredLightImage>>,
    punctual: Vec<PunctualLight>,
    /// One per light (or empty: none moves in its plane).
    moves_in_plane: Vec<bool>,
    suns: Vec<SunLight>,
    /// One per material (or empty: every surface is opaque).
    cutouts: Vec<Option<StoredCutout>>,
    /// One per material (or empty: no texture is transformed): the UV transforms of its
    /// maps' textures — the base colour's (or `map_Kd`'s), the metallic-roughness one's.
    map_transforms: Vec<[Option<UvTransform>; 2]>,
    /// One per material (or empty: none is normal-mapped).
    normal_maps: Vec<Option<StoredNormalMap>>,
}

/// A material's [`NormalMap`], its texture an index into `StoredScene::textures`.
#[derive(Serialize, Deserialize)]
struct StoredNormalMap {
    texture: StoredTextureRef,
    transform: Option<UvTransform>,
    scale: f32,
}

/// Version 8: version 9 without the normal maps.
#[derive(Serialize, Deserialize)]
struct StoredSceneV8 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
    uvs: Vec<[f32; 2]>,
    textures: Vec<StoredTexture>,
    maps: Vec<Option<StoredMaps>>,
    light_images: Vec<Option<StoredLightImage>>,
    punctual: Vec<PunctualLight>,
    moves_in_plane: Vec<bool>,
    suns: Vec<SunLight>,
    cutouts: Vec<Option<StoredCutout>>,
    map_transforms: Vec<[Option<UvTransform>; 2]>,
}

impl From<StoredSceneV8> for StoredScene<'static> {
    fn from(v: StoredSceneV8) -> StoredScene<'static> {
        StoredScene {
            version: v.version,
            mesh: Cow::Owned(v.mesh),
            materials: v.materials,
            lights: v.lights,
            camera: v.camera,
            bake: v.bake,
            motion: v.motion,
            uvs: v.uvs,
            textures: v.textures,
            maps: v.maps,
            light_images: v.light_images,
            punctual: v.punctual,
            moves_in_plane: v.moves_in_plane,
            suns: v.suns,
            cutouts: v.cutouts,
            map_transforms: v.map_transforms,
            normal_maps: Vec::new(),
        }
    }
}

/// A material's [`Cutout`], its texture an index into `StoredScene::textures`.
#[derive(Serialize, Deserialize)]
struct StoredCutout {
    alpha: f32,
    cutoff: f32,
    texture: Option<StoredTextureRef>,
    transform: Option<UvTransform>,
    blend: bool,
}

/// Version 7: version 8 without the cut-outs.
#[derive(Serialize, Deserialize)]
struct StoredSceneV7 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
    uvs: Vec<[f32; 2]>,
    textures: Vec<StoredTexture>,
    maps: Vec<Option<StoredMaps>>,
    light_images: Vec<Option<StoredLightImage>>,
    punctual: Vec<PunctualLight>,
    moves_in_plane: Vec<bool>,
    suns: Vec<SunLight>,
}

impl From<StoredSceneV7> for StoredScene<'static> {
    fn from(v: StoredSceneV7) -> StoredScene<'static> {
        StoredScene {
            version: v.version,
            mesh: Cow::Owned(v.mesh),
            materials: v.materials,
            lights: v.lights,
            camera: v.camera,
            bake: v.bake,
            motion: v.motion,
            uvs: v.uvs,
            textures: v.textures,
            maps: v.maps,
            light_images: v.light_images,
            punctual: v.punctual,
            moves_in_plane: v.moves_in_plane,
            suns: v.suns,
            cutouts: Vec::new(),
            map_transforms: Vec::new(),
            normal_maps: Vec::new(),
        }
    }
}

/// Version 6: version 7 with punctual lights without a radius and no suns.
#[derive(Serialize, Deserialize)]
struct StoredSceneV6 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
    uvs: Vec<[f32; 2]>,
    textures: Vec<StoredTexture>,
    maps: Vec<Option<StoredMaps>>,
    light_images: Vec<Option<StoredLightImage>>,
    punctual: Vec<PunctualV6>,
    moves_in_plane: Vec<bool>,
}

/// A punctual light as versions 5 and 6 stored it (no radius: the default's).
#[derive(Serialize, Deserialize)]
struct PunctualV6 {
    name: String,
    position: [f32; 3],
    intensity: [f32; 3],
    range: Option<f32>,
    spot: Option<Spot>,
}

impl From<PunctualV6> for PunctualLight {
    fn from(p: PunctualV6) -> PunctualLight {
        PunctualLight {
            name: p.name,
            position: p.position,
            intensity: p.intensity,
            range: p.range,
            spot: p.spot,
            radius: None,
        }
    }
}

impl From<StoredSceneV6> for StoredScene<'static> {
    fn from(v: StoredSceneV6) -> StoredScene<'static> {
        StoredSceneV7 {
            version: v.version,
            mesh: v.mesh,
            materials: v.materials,
            lights: v.lights,
            camera: v.camera,
            bake: v.bake,
            motion: v.motion,
            uvs: v.uvs,
            textures: v.textures,
            maps: v.maps,
            light_images: v.light_images,
            punctual: v.punctual.into_iter().map(PunctualLight::from).collect(),
            moves_in_plane: v.moves_in_plane,
            suns: Vec::new(),
        }
        .into()
    }
}

/// Version 5: version 6 without `moves_in_plane` (every light without a region moved in its
/// plane).
#[derive(Serialize, Deserialize)]
struct StoredSceneV5 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
    uvs: Vec<[f32; 2]>,
    textures: Vec<StoredTexture>,
    maps: Vec<Option<StoredMaps>>,
    light_images: Vec<Option<StoredLightImage>>,
    punctual: Vec<PunctualV6>,
}

impl From<StoredSceneV5> for StoredScene<'static> {
    fn from(v: StoredSceneV5) -> StoredScene<'static> {
        let moves_in_plane = v.lights.iter().map(|l| l.region.is_none()).collect();
        StoredSceneV6 {
            version: v.version,
            mesh: v.mesh,
            materials: v.materials,
            lights: v.lights,
            camera: v.camera,
            bake: v.bake,
            motion: v.motion,
            uvs: v.uvs,
            textures: v.textures,
            maps: v.maps,
            light_images: v.light_images,
            punctual: v.punctual,
            moves_in_plane,
        }
        .into()
    }
}

/// Version 4: version 5 without textures, UVs and punctual lights.
#[derive(Serialize, Deserialize)]
struct StoredSceneV4 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: StoredCamera,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
}

/// A [`Texture`]: the PNG or JPEG it was decoded from (decoded again, with the same limits,
/// when read), or for a texture made in memory its RGBA8 texels zstd-compressed.
#[derive(Serialize, Deserialize)]
struct StoredTexture {
    name: String,
    pixels: StoredPixels,
}

#[derive(Serialize, Deserialize)]
enum StoredPixels {
    Encoded(Vec<u8>),
    Rgba8Zstd {
        width: u32,
        height: u32,
        rgba_zstd: Vec<u8>,
    },
}

#[derive(Serialize, Deserialize)]
struct StoredTextureRef {
    texture: u32,
    wrap: [Wrap; 2],
}

/// [`MaterialMaps`] with its textures as indices into `StoredScene::textures`.
#[derive(Serialize, Deserialize)]
enum StoredMaps {
    MetallicRoughness {
        base_color: [f32; 3],
        metallic: f32,
        roughness: f32,
        base_color_texture: Option<StoredTextureRef>,
        metallic_roughness_texture: Option<StoredTextureRef>,
    },
    Diffuse {
        kd: [f32; 3],
        texture: StoredTextureRef,
    },
}

#[derive(Serialize, Deserialize)]
struct StoredLightImage {
    width: u32,
    height: u32,
    texels: Vec<[f32; 3]>,
}

/// The scene's textures, each image once (shared `Arc`s are one image).
struct TextureTable {
    images: Vec<Arc<Texture>>,
}

impl TextureTable {
    fn index(&mut self, t: &TextureRef) -> StoredTextureRef {
        let i = match self.images.iter().position(|x| Arc::ptr_eq(x, &t.texture)) {
            Some(i) => i,
            None => {
                self.images.push(t.texture.clone());
                self.images.len() - 1
            }
        };
        StoredTextureRef {
            texture: i as u32,
            wrap: t.wrap,
        }
    }

    fn maps(&mut self, m: &MaterialMaps) -> StoredMaps {
        match m {
            MaterialMaps::MetallicRoughness {
                base_color,
                metallic,
                roughness,
                base_color_texture,
                metallic_roughness_texture,
            } => StoredMaps::MetallicRoughness {
                base_color: *base_color,
                metallic: *metallic,
                roughness: *roughness,
                base_color_texture: base_color_texture.as_ref().map(|t| self.index(t)),
                metallic_roughness_texture: metallic_roughness_texture
                    .as_ref()
                    .map(|t| self.index(t)),
            },
            MaterialMaps::Diffuse { kd, texture } => StoredMaps::Diffuse {
                kd: *kd,
                texture: self.index(texture),
            },
        }
    }
}

fn store_texture(t: &Texture) -> StoredTexture {
    StoredTexture {
        name: t.name.clone(),
        pixels: if t.source.is_empty() {
            StoredPixels::Rgba8Zstd {
                width: t.width,
                height: t.height,
                rgba_zstd: zstd::bulk::compress(&t.rgba, 3).unwrap_or_default(),
            }
        } else {
            StoredPixels::Encoded(t.source.clone())
        },
    }
}

fn load_texture(t: StoredTexture) -> Result<Arc<Texture>, String> {
    let bad = |e: String| format!("stored texture {:?}: {e}", t.name);
    let (width, height, rgba_zstd) = match t.pixels {
        StoredPixels::Encoded(bytes) => {
            return Texture::decode(&bytes, &t.name).map(Arc::new).map_err(bad);
        }
        StoredPixels::Rgba8Zstd {
            width,
            height,
            rgba_zstd,
        } => (width, height, rgba_zstd),
    };
    let texels = u64::from(width) * u64::from(height);
    if width == 0
        || height == 0
        || width > crate::texture::MAX_TEXTURE_SIDE
        || height > crate::texture::MAX_TEXTURE_SIDE
        || texels > crate::texture::MAX_TEXTURE_TEXELS
    {
        return Err(bad(format!("invalid size {width}×{height}")));
    }
    let len = 4 * texels as usize;
    let rgba = zstd::bulk::decompress(&rgba_zstd, len)
        .map_err(|e| bad(format!("does not decompress: {e}")))?;
    if rgba.len() != len {
        return Err(bad(format!(
            "{} bytes for {width}×{height} texels",
            rgba.len()
        )));
    }
    Ok(Arc::new(Texture {
        name: t.name,
        width,
        height,
        rgba,
        source: Vec::new(),
        mips: Default::default(),
    }))
}

fn texture_ref(r: StoredTextureRef, textures: &[Arc<Texture>]) -> Result<TextureRef, String> {
    let texture = textures
        .get(r.texture as usize)
        .cloned()
        .ok_or_else(|| format!("stored material names texture {}", r.texture))?;
    Ok(TextureRef {
        texture,
        wrap: r.wrap,
        transform: None,
    })
}

fn load_maps(m: StoredMaps, textures: &[Arc<Texture>]) -> Result<MaterialMaps, String> {
    let get = |r: StoredTextureRef| texture_ref(r, textures);
    Ok(match m {
        StoredMaps::MetallicRoughness {
            base_color,
            metallic,
            roughness,
            base_color_texture,
            metallic_roughness_texture,
        } => MaterialMaps::MetallicRoughness {
            base_color,
            metallic,
            roughness,
            base_color_texture: base_color_texture.map(get).transpose()?,
            metallic_roughness_texture: metallic_roughness_texture.map(get).transpose()?,
        },
        StoredMaps::Diffuse { kd, texture } => MaterialMaps::Diffuse {
            kd,
            texture: get(texture)?,
        },
    })
}

/// Version 3: [`StoredScene`] with [`CameraV3`].
#[derive(Serialize, Deserialize)]
struct StoredSceneV3 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: CameraV3,
    bake: BakeSettings,
    motion: Vec<MovingPart>,
}

/// Version 2: version 3 with [`BakeSettingsV2`].
#[derive(Serialize, Deserialize)]
struct StoredSceneV2 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: CameraV3,
    bake: BakeSettingsV2,
    motion: Vec<MovingPart>,
}

/// Version 1: version 2 without `motion`.
#[derive(Serialize, Deserialize)]
struct StoredSceneV1 {
    version: u16,
    mesh: Mesh,
    materials: Vec<Material>,
    lights: Vec<StoredLight>,
    camera: CameraV3,
    bake: BakeSettingsV2,
}

/// [`Camera`] without serde's skipped fields, which postcard cannot carry.
#[derive(Serialize, Deserialize)]
struct StoredCamera {
    position: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    fov_y_deg: f32,
    aspect: Option<f32>,
}

impl From<&Camera> for StoredCamera {
    fn from(c: &Camera) -> StoredCamera {
        StoredCamera {
            position: c.position,
            target: c.target,
            up: c.up,
            fov_y_deg: c.fov_y_deg,
            aspect: c.aspect,
        }
    }
}

impl From<StoredCamera> for Camera {
    fn from(c: StoredCamera) -> Camera {
        Camera {
            position: c.position,
            target: c.target,
            up: c.up,
            fov_y_deg: c.fov_y_deg,
            aspect: c.aspect,
        }
    }
}

/// [`Camera`] before `aspect` (versions 1 to 3).
#[derive(Serialize, Deserialize)]
struct CameraV3 {
    position: [f32; 3],
    target: [f32; 3],
    up: [f32; 3],
    fov_y_deg: f32,
}

impl From<CameraV3> for StoredCamera {
    fn from(c: CameraV3) -> StoredCamera {
        StoredCamera {
            position: c.position,
            target: c.target,
            up: c.up,
            fov_y_deg: c.fov_y_deg,
            aspect: None,
        }
    }
}

/// [`BakeSettings`] before `refine` (versions 1 and 2).
#[derive(Serialize, Deserialize)]
struct BakeSettingsV2 {
    face_res: u32,
    epsilon: f32,
    supersampling: u32,
    split: crate::scene::SplitMethod,
    chunk_vertices: u32,
}

impl From<BakeSettingsV2> for BakeSettings {
    fn from(b: BakeSettingsV2) -> BakeSettings {
        BakeSettings {
            face_res: b.face_res,
            epsilon: b.epsilon,
            supersampling: b.supersampling,
            split: b.split,
            chunk_vertices: b.chunk_vertices,
            refine: None,
        }
    }
}

/// [`PolygonLight`] without serde's skipped fields, which postcard cannot carry.
#[derive(Serialize, Deserialize)]
struct StoredLight {
    vertices: Vec<[f32; 3]>,
    radiance: [f32; 3],
    two_sided: bool,
    texture: Option<String>,
    region: Option<Region>,
}

impl From<&PolygonLight> for StoredLight {
    fn from(l: &PolygonLight) -> StoredLight {
        StoredLight {
            vertices: l.vertices.clone(),
            radiance: l.radiance,
            two_sided: l.two_sided,
            texture: l.texture.clone(),
            region: l.region,
        }
    }
}

/// The scene as stored in `scene.bin` (postcard; exact floats).
pub fn encode_scene(s: &Scene) -> Vec<u8> {
    let mut table = TextureTable { images: Vec::new() };
    let maps: Vec<Option<StoredMaps>> = if s.materials.iter().any(|m| m.maps.is_some()) {
        s.materials
            .iter()
            .map(|m| m.maps.as_ref().map(|x| table.maps(x)))
            .collect()
    } else {
        Vec::new()
    };
    let cutouts: Vec<Option<StoredCutout>> = if s.materials.iter().any(|m| m.cutout.is_some()) {
        s.materials
            .iter()
            .map(|m| {
                m.cutout.as_ref().map(|c| StoredCutout {
                    alpha: c.alpha,
                    cutoff: c.cutoff,
                    texture: c.texture.as_ref().map(|t| table.index(t)),
                    transform: c.texture.as_ref().and_then(|t| t.transform),
                    blend: c.blend,
                })
            })
            .collect()
    } else {
        Vec::new()
    };
    let transforms = |m: &Material| -> [Option<UvTransform>; 2] {
        match &m.maps {
            Some(MaterialMaps::MetallicRoughness {
                base_color_texture,
                metallic_roughness_texture,
                ..
            }) => [
                base_color_texture.as_ref().and_then(|t| t.transform),
                metallic_roughness_texture
                    .as_ref()
                    .and_then(|t| t.transform),
            ],
            Some(MaterialMaps::Diffuse { texture, .. }) => [texture.transform, None],
            None => [None, None],
        }
    };
    let map_transforms = if s.materials.iter().any(|m| transforms(m) != [None, None]) {
        s.materials.iter().map(transforms).collect()
    } else {
        Vec::new()
    };
    let normal_maps: Vec<Option<StoredNormalMap>> =
        if s.materials.iter().any(|m| m.normal_map.is_some()) {
            s.materials
                .iter()
                .map(|m| {
                    m.normal_map.as_ref().map(|n| StoredNormalMap {
                        texture: table.index(&n.texture),
                        transform: n.texture.transform,
                        scale: n.scale,
                    })
                })
                .collect()
        } else {
            Vec::new()
        };
    let light_images = if s.lights.iter().any(|l| l.image.is_some()) {
        s.lights
            .iter()
            .map(|l| {
                l.image.as_ref().map(|i| StoredLightImage {
                    width: i.width,
                    height: i.height,
                    texels: i.texels.clone(),
                })
            })
            .collect()
    } else {
        Vec::new()
    };
    let stored = StoredScene {
        version: STORED_VERSION,
        mesh: Cow::Borrowed(&s.mesh),
        materials: s.materials.clone(),
        lights: s.lights.iter().map(StoredLight::from).collect(),
        camera: StoredCamera::from(&s.camera),
        bake: s.bake.clone(),
        motion: s.motion.clone(),
        uvs: s.mesh.uvs.iter().map(|v| v.to_array()).collect(),
        textures: table.images.iter().map(|t| store_texture(t)).collect(),
        maps,
        light_images,
        punctual: s.punctual.clone(),
        moves_in_plane: match s.lights.iter().any(|l| l.moves_in_plane) {
            true => s.lights.iter().map(|l| l.moves_in_plane).collect(),
            false => Vec::new(),
        },
        suns: s.suns.clone(),
        cutouts,
        map_transforms,
        normal_maps,
    };
    postcard::to_stdvec(&stored).unwrap_or_default()
}

/// Version 4 and before: nothing textured, no punctual lights.
fn from_v4(v: StoredSceneV4) -> StoredScene<'static> {
    StoredSceneV5 {
        version: v.version,
        mesh: v.mesh,
        materials: v.materials,
        lights: v.lights,
        camera: v.camera,
        bake: v.bake,
        motion: v.motion,
        uvs: Vec::new(),
        textures: Vec::new(),
        maps: Vec::new(),
        light_images: Vec::new(),
        punctual: Vec::new(),
    }
    .into()
}

/// Reads back [`encode_scene`]'s bytes (and version 1's).
pub fn decode_scene(bytes: &[u8]) -> Result<Scene, String> {
    let bad = |e: postcard::Error| format!("stored scene does not decode: {e}");
    let (version, _) = postcard::take_from_bytes::<u16>(bytes).map_err(bad)?;
    let s = match version {
        1 => {
            let v1: StoredSceneV1 = postcard::from_bytes(bytes).map_err(bad)?;
            from_v4(StoredSceneV4 {
                version: v1.version,
                mesh: v1.mesh,
                materials: v1.materials,
                lights: v1.lights,
                camera: v1.camera.into(),
                bake: v1.bake.into(),
                motion: Vec::new(),
            })
        }
        2 => {
            let v2: StoredSceneV2 = postcard::from_bytes(bytes).map_err(bad)?;
            from_v4(StoredSceneV4 {
                version: v2.version,
                mesh: v2.mesh,
                materials: v2.materials,
                lights: v2.lights,
                camera: v2.camera.into(),
                bake: v2.bake.into(),
                motion: v2.motion,
            })
        }
        3 => {
            let v3: StoredSceneV3 = postcard::from_bytes(bytes).map_err(bad)?;
            from_v4(StoredSceneV4 {
                version: v3.version,
                mesh: v3.mesh,
                materials: v3.materials,
                lights: v3.lights,
                camera: v3.camera.into(),
                bake: v3.bake,
                motion: v3.motion,
            })
        }
        4 => from_v4(postcard::from_bytes(bytes).map_err(bad)?),
        5 => postcard::from_bytes::<StoredSceneV5>(bytes)
            .map_err(bad)?
            .into(),
        6 => postcard::from_bytes::<StoredSceneV6>(bytes)
            .map_err(bad)?
            .into(),
        7 => postcard::from_bytes::<StoredSceneV7>(bytes)
            .map_err(bad)?
            .into(),
        8 => postcard::from_bytes::<StoredSceneV8>(bytes)
            .map_err(bad)?
            .into(),
        STORED_VERSION => postcard::from_bytes(bytes).map_err(bad)?,
        v => return Err(format!("stored scene has version {v}")),
    };
    let textures = s
        .textures
        .into_iter()
        .map(load_texture)
        .collect::<Result<Vec<_>, String>>()?;
    let mut materials = s.materials;
    if !s.maps.is_empty() {
        if s.maps.len() != materials.len() {
            return Err("stored scene: texture maps do not match the materials".into());
        }
        for (m, maps) in materials.iter_mut().zip(s.maps) {
            m.maps = maps.map(|x| load_maps(x, &textures)).transpose()?;
        }
    }
    if !s.map_transforms.is_empty() {
        if s.map_transforms.len() != materials.len() {
            return Err("stored scene: texture transforms do not match the materials".into());
        }
        for (m, [first, second]) in materials.iter_mut().zip(s.map_transforms) {
            match &mut m.maps {
                Some(MaterialMaps::MetallicRoughness {
                    base_color_texture,
                    metallic_roughness_texture,
                    ..
                }) => {
                    if let Some(t) = base_color_texture {
                        t.transform = first;
                    }
                    if let Some(t) = metallic_roughness_texture {
                        t.transform = second;
                    }
                }
                Some(MaterialMaps::Diffuse { texture, .. }) => texture.transform = first,
                None => {}
            }
        }
    }
    if !s.cutouts.is_empty() {
        if s.cutouts.len() != materials.len() {
            return Err("stored scene: cut-outs do not match the materials".into());
        }
        for (m, c) in materials.iter_mut().zip(s.cutouts) {
            m.cutout = c
                .map(|c| -> Result<Cutout, String> {
                    Ok(Cutout {
                        alpha: c.alpha,
                        cutoff: c.cutoff,
                        texture: c
                            .texture
                            .map(|r| texture_ref(r, &textures))
                            .transpose()?
                            .map(|t| TextureRef {
                                transform: c.transform,
                                ..t
                            }),
                        blend: c.blend,
                    })
                })
                .transpose()?;
        }
    }
    if !s.normal_maps.is_empty() {
        if s.normal_maps.len() != materials.len() {
            return Err("stored scene: normal maps do not match the materials".into());
        }
        for (m, n) in materials.iter_mut().zip(s.normal_maps) {
            m.normal_map = n
                .map(|n| -> Result<NormalMap, String> {
                    Ok(NormalMap {
                        texture: TextureRef {
                            transform: n.transform,
                            ..texture_ref(n.texture, &textures)?
                        },
                        scale: n.scale,
                    })
                })
                .transpose()?;
        }
    }
    if !s.light_images.is_empty() && s.light_images.len() != s.lights.len() {
        return Err("stored scene: light images do not match the lights".into());
    }
    if !s.moves_in_plane.is_empty() && s.moves_in_plane.len() != s.lights.len() {
        return Err("stored scene: the lights' motions do not match the lights".into());
    }
    let mut images = s.light_images.into_iter();
    let mut in_plane = s.moves_in_plane.into_iter();
    let mut mesh = s.mesh.into_owned();
    mesh.uvs = s.uvs.into_iter().map(glam::Vec2::from).collect();
    let scene = Scene {
        mesh,
        materials,
        lights: s
            .lights
            .into_iter()
            .map(|l| PolygonLight {
                vertices: l.vertices,
                radiance: l.radiance,
                two_sided: l.two_sided,
                texture: l.texture,
                region: l.region,
                moves_in_plane: in_plane.next().unwrap_or(false),
                image: images.next().flatten().map(|i| {
                    Arc::new(LightImage {
                        width: i.width,
                        height: i.height,
                        texels: i.texels,
                    })
                }),
            })
            .collect(),
        punctual: s.punctual,
        suns: s.suns,
        environment: None,
        camera: s.camera.into(),
        bake: s.bake,
        motion: s.motion,
        warnings: Vec::new(),
    };
    scene
        .validate()
        .map_err(|e| format!("stored scene is not valid: {e}"))?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A version-1 stored scene (static, before motion) still reads.
    #[test]
    fn version_1_reads() {
        let p = crate::builtin::scene("plate-small").expect("builtin");
        let v1 = postcard::to_stdvec(&StoredSceneV1 {
            version: 1,
            mesh: p.mesh.clone(),
            materials: p.materials.clone(),
            lights: p.lights.iter().map(StoredLight::from).collect(),
            camera: v3_camera(&p.camera),
            bake: v2_settings(&p.bake),
        })
        .expect("encode v1");
        assert_eq!(decode_scene(&v1).as_ref(), Ok(&p));
        assert_eq!(decode_scene(&encode_scene(&p)).as_ref(), Ok(&p));
    }

    /// A scene as stored before version 6 reads back: every light without a region moved in
    /// its plane.
    fn before_fixed_lamps(s: &mut Scene) {
        for l in &mut s.lights {
            l.moves_in_plane = l.region.is_none();
        }
    }

    /// A version-6 stored scene with punctual lights (before their radii and the suns) reads
    /// back with the default radius and no suns; the punctual room (point, spot, sun)
    /// round-trips in version 7.
    #[test]
    fn version_6_punctual_lights_read_and_version_7_round_trips() {
        let mut p = crate::builtin::scene("punctual-room").expect("builtin");
        p.warnings.clear();
        assert_eq!((p.punctual.len(), p.suns.len()), (2, 1));
        assert_eq!(decode_scene(&encode_scene(&p)).as_ref(), Ok(&p));
        let v6 = postcard::to_stdvec(&StoredSceneV6 {
            version: 6,
            mesh: p.mesh.clone(),
            materials: p.materials.clone(),
            lights: Vec::new(),
            camera: StoredCamera::from(&p.camera),
            bake: p.bake.clone(),
            motion: Vec::new(),
            uvs: Vec::new(),
            textures: Vec::new(),
            maps: Vec::new(),
            light_images: Vec::new(),
            punctual: p
                .punctual
                .iter()
                .map(|l| PunctualV6 {
                    name: l.name.clone(),
                    position: l.position,
                    intensity: l.intensity,
                    range: l.range,
                    spot: l.spot,
                })
                .collect(),
            moves_in_plane: Vec::new(),
        })
        .expect("encode v6");
        let back = decode_scene(&v6).expect("v6 reads");
        assert!(back.suns.is_empty());
        assert_eq!(back.punctual.len(), 2);
        assert!(back.punctual.iter().all(|l| l.radius.is_none()));
        assert_eq!(back.punctual[0].position, p.punctual[0].position);
    }

    fn v3_camera(c: &Camera) -> CameraV3 {
        CameraV3 {
            position: c.position,
            target: c.target,
            up: c.up,
            fov_y_deg: c.fov_y_deg,
        }
    }

    /// A version-3 stored scene (before the camera's `aspect`) still reads, with none; a
    /// version-4 scene with an aspect round-trips.
    #[test]
    fn version_3_reads_and_the_camera_aspect_round_trips() {
        let mut p = crate::builtin::scene("room").expect("builtin");
        p.warnings.clear();
        assert_eq!(p.camera.aspect, Some(1.5), "the glTF room's camera");
        assert_eq!(decode_scene(&encode_scene(&p)).as_ref(), Ok(&p));
        let v3 = postcard::to_stdvec(&StoredSceneV3 {
            version: 3,
            mesh: p.mesh.clone(),
            materials: p.materials.clone(),
            lights: p.lights.iter().map(StoredLight::from).collect(),
            camera: v3_camera(&p.camera),
            bake: p.bake.clone(),
            motion: p.motion.clone(),
        })
        .expect("encode v3");
        p.camera.aspect = None;
        before_fixed_lamps(&mut p);
        assert_eq!(decode_scene(&v3).as_ref(), Ok(&p));
    }

    fn v2_settings(b: &BakeSettings) -> BakeSettingsV2 {
        BakeSettingsV2 {
            face_res: b.face_res,
            epsilon: b.epsilon,
            supersampling: b.supersampling,
            split: b.split,
            chunk_vertices: b.chunk_vertices,
        }
    }

    /// A version-2 stored scene (before `bake.refine`) still reads, with no refinement; a
    /// version-3 scene with refinement round-trips.
    #[test]
    fn version_2_reads_and_refinement_round_trips() {
        let mut p = crate::builtin::scene("dynamic").expect("builtin");
        let v2 = postcard::to_stdvec(&StoredSceneV2 {
            version: 2,
            mesh: p.mesh.clone(),
            materials: p.materials.clone(),
            lights: p.lights.iter().map(StoredLight::from).collect(),
            camera: v3_camera(&p.camera),
            bake: v2_settings(&p.bake),
            motion: p.motion.clone(),
        })
        .expect("encode v2");
        p.warnings.clear();
        let fixed = p.clone();
        before_fixed_lamps(&mut p);
        assert_eq!(decode_scene(&v2).as_ref(), Ok(&p));
        let mut p = fixed;
        p.bake.refine = Some(crate::scene::Refinement {
            tolerance: 0.25,
            lighting: 0.0,
            min_edge: 0.01,
            max_vertices: 1234,
        });
        assert_eq!(decode_scene(&encode_scene(&p)).as_ref(), Ok(&p));
    }

    /// A version-4 stored scene (before textures and punctual lights) still reads, with
    /// none; the version-9 encoding of an untextured scene without lights moving in their
    /// planes, punctual lights, suns, cut-outs, texture transforms or normal maps is version
    /// 4's and ten empty lists.
    #[test]
    fn version_4_reads() {
        let mut p = crate::builtin::scene("room").expect("builtin");
        p.warnings.clear();
        let v4 = postcard::to_stdvec(&StoredSceneV4 {
            version: 4,
            mesh: p.mesh.clone(),
            materials: p.materials.clone(),
            lights: p.lights.iter().map(StoredLight::from).collect(),
            camera: StoredCamera::from(&p.camera),
            bake: p.bake.clone(),
            motion: p.motion.clone(),
        })
        .expect("encode v4");
        // Before version 6 every light without a region moved in its plane.
        let mut moving = p.clone();
        for l in &mut moving.lights {
            l.moves_in_plane = l.region.is_none();
        }
        assert!(moving.lights.iter().any(|l| l.moves_in_plane));
        assert_eq!(decode_scene(&v4).as_ref(), Ok(&moving));
        let v9 = encode_scene(&p);
        assert_eq!(v9.len(), v4.len() + 10, "the ten empty lists");
        assert_eq!(decode_scene(&v9).as_ref(), Ok(&p));
        // A light that moves in its plane round-trips.
        assert_eq!(decode_scene(&encode_scene(&moving)).as_ref(), Ok(&moving));
    }

    #[test]
    fn job_states_round_trip_through_their_names() {
        for s in [
            JobState::Queued,
            JobState::Baking,
            JobState::Done,
            JobState::Failed,
            JobState::Cancelled,
        ] {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
        }
        assert_eq!(JobState::parse("paused"), None);
    }
}
