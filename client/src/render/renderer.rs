//! One camera, many frames: the G-buffer is rasterised once, then every frame shades the
//! vertices the camera sees (per-vertex mode) or the pixels (per-pixel mode) for the light's
//! current pose.
//!
//! - Per vertex (paper 000): BSPVT-shaded radiance at each visible vertex, interpolated over
//!   the triangles.
//! - Per pixel: unshadowed LTC evaluated at every pixel, times the per-vertex shadow ratios
//!   (shadowed / unshadowed, one for the diffuse and one for the specular lobe) interpolated —
//!   highlights as sharp as per-pixel LTC, shadows as smooth as the mesh.

use bspvt_proto::Scene;
use bspvt_proto::bspvt::{LineCodec, VertexTrees};
use bspvt_proto::scene::{Camera, Material};
use glam::DVec3;
use rayon::prelude::*;

use crate::frame::camera::View;
use crate::frame::gbuffer::{GBuffer, NONE, Surface};
use crate::frame::image::Image;
use crate::frame::normal_map::NormalMaps;
use crate::light::Light;
use crate::ltc::table::LtcTable;
use crate::shade::bspvt::shade_vertex;
use crate::shade::sky::{shade_vertex_sky, unshadowed_sky};
use crate::shade::{Lobes, Shaded, ShadowRatio, UNSHADOWED, unshadowed, unshadowed_lights};

/// Where shading is evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Per vertex, interpolated over triangles (the paper's).
    Vertex,
    /// Unshadowed LTC per pixel × interpolated per-vertex shadow ratios.
    Pixel,
}

/// Baked visibility for the BSPVT method.
pub struct Trees<'a> {
    /// One tree set per vertex, in vertex order.
    pub trees: &'a [VertexTrees],
    /// The bake's line codec.
    pub codec: LineCodec,
    /// While trees stream in: which vertices have theirs. The others are shaded unshadowed
    /// (shadow ratio 1) until they arrive. `None`: all are present.
    pub(crate) present: Option<&'a [bool]>,
}

impl<'a> Trees<'a> {
    /// A complete bake.
    pub fn full(trees: &'a [VertexTrees], codec: LineCodec) -> Trees<'a> {
        Trees {
            trees,
            codec,
            present: None,
        }
    }

    /// Trees streamed in part: vertex `v` has its trees where `present[v]` (the others are
    /// shaded unshadowed).
    pub fn partial(trees: &'a [VertexTrees], codec: LineCodec, present: &'a [bool]) -> Trees<'a> {
        Trees {
            trees,
            codec,
            present: Some(present),
        }
    }

    /// A key of which trees these are: the same slice with the same vertices present.
    pub(crate) fn key(&self) -> (usize, usize, usize) {
        let present = self
            .present
            .map_or(self.trees.len(), |p| p.iter().filter(|&&b| b).count());
        (self.trees.as_ptr() as usize, self.trees.len(), present)
    }

    /// Whether vertex `v` has its trees.
    pub(crate) fn has(&self, v: u32) -> bool {
        self.present
            .is_none_or(|p| p.get(v as usize).copied().unwrap_or(false))
            && (v as usize) < self.trees.len()
    }
}

/// Counters of one frame.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct FrameCounts {
    /// Vertices shaded (per-vertex shading).
    pub vertices_shaded: usize,
    pub(crate) pixels_shaded: usize,
    /// BSPVT pieces integrated (v̄ > 0).
    pub pieces: u64,
    /// BSPVT pieces dropped (v̄ = 0).
    pub pieces_dropped: u64,
}

/// A camera on a scene: its G-buffer, and per-vertex or per-pixel LTC and BSPVT frames.
pub struct Renderer<'a> {
    pub(crate) scene: &'a Scene,
    /// The camera.
    pub view: View,
    /// Primary visibility of the camera.
    pub gbuffer: GBuffer,
    /// Vertices of the triangles the camera sees.
    pub(crate) visible_vertices: Vec<u32>,
    /// Per vertex, whether the camera sees it from behind
    /// ([`GBuffer::vertex_sides`]): shaded per vertex on that side, unshadowed.
    seen_from_behind: Vec<bool>,
    /// Material of each vertex (that of the first triangle using it).
    pub(crate) vertex_material: Vec<u32>,
    pub(crate) table: &'static LtcTable,
    /// The scene's materials, with the roughness override applied.
    materials: Vec<Material>,
    /// The roughness override (applied again after a texture lookup).
    roughness: Option<f32>,
    /// The scene's alpha cut-outs, which the G-buffer sees through.
    pub(crate) cut: Option<std::sync::Arc<bspvt_raytrace::Cutouts>>,
    /// The scene's normal maps, which bend the shading normals of pixels and vertices.
    pub(crate) normal_maps: Option<std::sync::Arc<NormalMaps>>,
}

impl<'a> Renderer<'a> {
    /// A renderer with the scene's camera at `width`×`height`.
    pub fn new(scene: &'a Scene, width: u32, height: u32) -> Renderer<'a> {
        Renderer::with_camera(scene, &scene.camera, width, height)
    }

    /// A renderer looking through `camera` instead of the scene's.
    pub fn with_camera(scene: &'a Scene, camera: &Camera, width: u32, height: u32) -> Renderer<'a> {
        let view = View::new(camera, width, height);
        let cut = bspvt_raytrace::Cutouts::of(&scene.mesh, &scene.materials);
        let normal_maps = NormalMaps::of(&scene.mesh, &scene.materials);
        let gbuffer = GBuffer::rasterize_cut(&scene.mesh, &view, cut.as_deref())
            .with_normal_maps(normal_maps.clone());
        let (visible_vertices, seen_from_behind) = seen(&gbuffer, &scene.mesh, view.eye);
        let vertex_material = bspvt_shaders::gpu::records::vertex_materials(&scene.mesh);
        Renderer {
            scene,
            view,
            gbuffer,
            visible_vertices,
            seen_from_behind,
            vertex_material,
            table: LtcTable::builtin(),
            materials: scene.materials.clone(),
            roughness: None,
            cut,
            normal_maps,
        }
    }

    /// The vertices a GPU frame shades: the visible vertices and every vertex of a triangle
    /// that touches one. The GPU's rasteriser may give a pixel centre to a neighbour of the
    /// triangle the CPU's G-buffer found there (ties on shared edges, sub-pixel triangles), and
    /// a vertex it then interpolates must have been shaded: unshaded, it reads as unshadowed
    /// (bright speckles along the far edge of a finely refined umbra: canopy.gltf, 13.2 % mean
    /// difference in the shadows against the CPU before, 3.5 % after; docs/gpu.md).
    pub(crate) fn gpu_shaded_vertices(&self) -> Vec<u32> {
        let mesh = &self.scene.mesh;
        let mut seen = vec![false; mesh.vertex_count()];
        for &v in &self.visible_vertices {
            seen[v as usize] = true;
        }
        let mut out = seen.clone();
        for t in &mesh.triangles {
            if t.iter().any(|&v| seen[v as usize]) {
                for &v in t {
                    out[v as usize] = true;
                }
            }
        }
        out.iter()
            .enumerate()
            .filter_map(|(v, &s)| s.then_some(v as u32))
            .collect()
    }

    /// Moves the camera: the G-buffer and the visible vertices follow.
    pub(crate) fn set_camera(&mut self, camera: &Camera) {
        let (w, h) = (self.gbuffer.width, self.gbuffer.height);
        self.view = View::new(camera, w, h);
        self.gbuffer = GBuffer::rasterize_cut(&self.scene.mesh, &self.view, self.cut.as_deref())
            .with_normal_maps(self.normal_maps.clone());
        (self.visible_vertices, self.seen_from_behind) =
            seen(&self.gbuffer, &self.scene.mesh, self.view.eye);
    }

    /// Overrides every material's GGX roughness α (`None`: the scene's own).
    pub(crate) fn set_roughness(&mut self, alpha: Option<f32>) {
        self.materials = self.scene.materials.clone();
        self.roughness = alpha;
        if let Some(a) = alpha {
            for m in &mut self.materials {
                m.roughness = a;
            }
        }
    }

    /// A key of everything a frame's shading depends on besides the lights and the trees:
    /// the camera and the materials (with the roughness override). Equal keys, equal shading.
    pub(crate) fn shading_key(&self) -> u64 {
        let v = &self.view;
        let mut h = bspvt_proto::hash::Fnv1a::default();
        for x in [v.eye, v.forward, v.right, v.up] {
            h.write(&x.x.to_le_bytes());
            h.write(&x.y.to_le_bytes());
            h.write(&x.z.to_le_bytes());
        }
        h.write(&v.tan_half_fov.to_le_bytes());
        h.write(&v.width.to_le_bytes());
        h.write(&v.height.to_le_bytes());
        for m in &self.materials {
            h.write_f32s(&[m.roughness]);
            h.write_f32s(&m.albedo);
            h.write_f32s(&m.specular);
        }
        h.finish()
    }

    /// The scene's materials with the roughness override applied.
    pub(crate) fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// The roughness override (`None`: the scene's own α).
    pub(crate) fn roughness_override(&self) -> Option<f32> {
        self.roughness
    }

    fn material(&self, id: u32) -> &Material {
        let m = &self.materials;
        &m[(id as usize).min(m.len().saturating_sub(1))]
    }

    /// Material `id` at texture coordinates `uv`: its textures looked up there (bilinear, the
    /// finest level), the roughness override applied after (`Material::at`).
    fn material_at(&self, id: u32, uv: Option<glam::Vec2>) -> std::borrow::Cow<'_, Material> {
        self.material_footprint(id, uv, None)
    }

    /// [`Self::material_at`] as a pixel with UV footprint `duv` sees it (the textures
    /// mipmapped, `Material::at_footprint`).
    fn material_footprint(
        &self,
        id: u32,
        uv: Option<glam::Vec2>,
        duv: Option<[glam::Vec2; 2]>,
    ) -> std::borrow::Cow<'_, Material> {
        let m = self.material(id);
        match m.at_footprint(uv, duv) {
            std::borrow::Cow::Owned(mut x) => {
                if let Some(a) = self.roughness {
                    x.roughness = a;
                }
                std::borrow::Cow::Owned(x)
            }
            b => b,
        }
    }

    /// Vertex `v`'s position, unit normal and material (per vertex, a textured material is
    /// the texture at the vertex's own UV (docs/scene-format.md "Textures"), interpolated over
    /// the triangle like the lighting).
    /// A vertex the camera sees from behind ([`Self::seen_from_behind`]) has its normal, and
    /// its whole tangent frame, turned over (as `gbuffer::shading_normal` per pixel).
    pub(crate) fn vertex_surface(&self, v: u32) -> (DVec3, DVec3, std::borrow::Cow<'_, Material>) {
        let p = self.scene.mesh.positions[v as usize].as_dvec3();
        let n = self.scene.mesh.normals[v as usize]
            .as_dvec3()
            .normalize_or(DVec3::Y);
        let id = self.vertex_material[v as usize];
        let side = if self.seen_from_behind(v) { -1.0 } else { 1.0 };
        let n = match self.normal_maps.as_ref() {
            None => side * n,
            Some(m) => {
                let wo = (self.view.eye - p).normalize_or(side * n);
                let bent = side * m.bend_vertex(&self.scene.mesh, v, id, n);
                NormalMaps::facing(bent, side * n, wo)
            }
        };
        let uv = self.scene.mesh.uvs.get(v as usize).copied();
        (p, n, self.material_at(id, uv))
    }

    /// Whether the camera sees vertex `v` from behind: it is then shaded on that side, where
    /// it has no trees — the bake covers the hemisphere its normal faces (docs/bake.md) — so
    /// unshadowed ([`Self::vertex_trees`]).
    pub(crate) fn seen_from_behind(&self, v: u32) -> bool {
        self.seen_from_behind
            .get(v as usize)
            .copied()
            .unwrap_or(false)
    }

    /// Vertex `v`'s trees for the side the camera sees: `None` while they have not arrived
    /// and for a vertex seen from behind.
    pub(crate) fn vertex_trees<'t>(&self, trees: &'t Trees, v: u32) -> Option<&'t VertexTrees> {
        (trees.has(v) && !self.seen_from_behind(v)).then(|| &trees.trees[v as usize])
    }

    pub(crate) fn vertex_lobes(&self, v: u32) -> (Lobes, DVec3, DVec3) {
        let (p, n, m) = self.vertex_surface(v);
        let wo = (self.view.eye - p).normalize_or(n);
        (Lobes::new(self.table, &m, n, wo), p, n)
    }

    /// Shades every visible vertex with `shade(v, lobes, p, n)` → (radiance, extra, pieces,
    /// dropped); vertices the camera does not see are left at zero. Returns the colours, each
    /// shaded vertex's `extra` and the counts.
    fn per_vertex<X: Send>(
        &self,
        shade: impl Fn(u32, &Lobes, DVec3, DVec3) -> ([f32; 3], X, u32, u32) + Sync,
    ) -> (Vec<[f32; 3]>, Vec<(u32, X)>, FrameCounts) {
        let n = self.scene.mesh.vertex_count();
        // (vertex, radiance, extra, pieces, dropped)
        let shaded: Vec<(u32, [f32; 3], X, u32, u32)> = self
            .visible_vertices
            .par_iter()
            .map(|&v| {
                let (lobes, p, nrm) = self.vertex_lobes(v);
                let (c, x, pieces, dropped) = shade(v, &lobes, p, nrm);
                (v, c, x, pieces, dropped)
            })
            .collect();
        let mut colour = vec![[0.0; 3]; n];
        let mut extra = Vec::with_capacity(shaded.len());
        let mut counts = FrameCounts {
            vertices_shaded: shaded.len(),
            ..FrameCounts::default()
        };
        for (v, c, x, pieces, dropped) in shaded {
            colour[v as usize] = c;
            extra.push((v, x));
            counts.pieces += u64::from(pieces);
            counts.pieces_dropped += u64::from(dropped);
        }
        (colour, extra, counts)
    }

    /// Vertices of the triangles the camera sees.
    pub fn visible_vertex_count(&self) -> usize {
        self.visible_vertices.len()
    }

    /// BSPVT per vertex: for every visible vertex, its shadowed radiance — the sum over
    /// `lights`, one tree set serving them all (docs/bake.md) — and, with `ratios`, each
    /// light's shadow ratios (`[light][vertex]`; empty without). Vertices the camera does not
    /// see are left at zero (ratio 1); a light a vertex cannot see costs a horizon test.
    pub fn shade_vertices(
        &self,
        lights: &[Light],
        trees: &Trees,
        ratios: bool,
    ) -> (Vec<[f32; 3]>, Vec<Vec<ShadowRatio>>, FrameCounts) {
        let k = if ratios { lights.len() } else { 0 };
        let mut per_light = vec![vec![UNSHADOWED; self.scene.mesh.vertex_count()]; k];
        let (colour, shaded, counts) = self.per_vertex(|v, lobes, p, nrm| {
            let mut sum = Shaded::default();
            let mut r = Vec::with_capacity(k);
            let (mut pieces, mut dropped) = (0, 0);
            let vt = self.vertex_trees(trees, v);
            for light in lights {
                let Some(vt) = vt else {
                    sum += unshadowed(lobes, light, p, nrm).tinted(light.radiance_toward(p));
                    continue;
                };
                let s = shade_vertex(lobes, light, p, nrm, vt, &trees.codec);
                sum += s.shadowed.tinted(light.radiance_toward(p));
                if ratios {
                    r.push(s.shadowed.ratio(&s.unshadowed));
                }
                pieces += s.pieces;
                dropped += s.dropped;
            }
            let c = lobes.radiance(DVec3::ONE, &sum);
            (c.as_vec3().to_array(), r, pieces, dropped)
        });
        for (v, r) in shaded {
            for (l, x) in r.into_iter().enumerate() {
                per_light[l][v as usize] = x;
            }
        }
        (colour, per_light, counts)
    }

    /// The sky through the baked sky trees per vertex ([`crate::shade::sky`]); vertices
    /// without trees yet are shaded unshadowed.
    pub(crate) fn shade_vertices_sky(
        &self,
        pieces: &[Light],
        trees: Option<&Trees>,
        ratios: bool,
    ) -> (Vec<[f32; 3]>, Vec<ShadowRatio>, FrameCounts) {
        let (colour, shaded, counts) = self.per_vertex(|v, lobes, _, nrm| {
            let Some((vt, t)) = trees.and_then(|t| Some((self.vertex_trees(t, v)?, t))) else {
                let s = unshadowed_sky(lobes, pieces, nrm);
                let c = lobes.radiance(DVec3::ONE, &s);
                return (c.as_vec3().to_array(), UNSHADOWED, 0, 0);
            };
            let r = shade_vertex_sky(lobes, pieces, nrm, vt, &t.codec, ratios);
            let c = lobes.radiance(DVec3::ONE, &r.shadowed);
            let ratio = if ratios { r.ratio() } else { UNSHADOWED };
            (c.as_vec3().to_array(), ratio, r.pieces, r.dropped)
        });
        let mut ratio = vec![UNSHADOWED; colour.len()];
        for (v, r) in shaded {
            ratio[v as usize] = r;
        }
        (colour, ratio, counts)
    }

    /// Unshadowed LTC per vertex (the "ltc" method in vertex mode), summed over `lights`.
    pub(crate) fn shade_vertices_unshadowed(&self, lights: &[Light]) -> Vec<[f32; 3]> {
        let n = self.scene.mesh.vertex_count();
        let shaded: Vec<(u32, [f32; 3])> = self
            .visible_vertices
            .par_iter()
            .map(|&v| {
                let (lobes, p, nrm) = self.vertex_lobes(v);
                let i = unshadowed_lights(&lobes, lights, p, nrm);
                (v, lobes.radiance(DVec3::ONE, &i).as_vec3().to_array())
            })
            .collect();
        let mut colour = vec![[0.0; 3]; n];
        for (v, c) in shaded {
            colour[v as usize] = c;
        }
        colour
    }

    /// The lamps themselves as the camera sees them: per pixel, the radiance of the light
    /// whose emitting side its camera ray meets nearer than the surface it sees (its
    /// texture's finest level there) — what the Monte Carlo's camera ray would find — or
    /// `None`.
    pub fn emitters(&self, lights: &[Light]) -> Vec<Option<[f32; 3]>> {
        let mut all = vec![None; self.gbuffer.tri.len()];
        let (start, seen) = self.emitters_in_rows(lights);
        all[start..start + seen.len()].copy_from_slice(&seen);
        all
    }

    /// [`Self::emitters`] over the rows a lamp may be seen in ([`lamp_box`]): the first
    /// pixel's index and the rows' pixels (none when no lamp is in view). A frame's lamps cost
    /// their own rows, not a ray per pixel of the image toward each.
    fn emitters_in_rows(&self, lights: &[Light]) -> (usize, Vec<Option<[f32; 3]>>) {
        let (mesh, g, view) = (&self.scene.mesh, &self.gbuffer, &self.view);
        let (w, h) = (g.width as usize, g.height as usize);
        let boxes: Vec<Option<[f64; 4]>> = lights.iter().map(|l| lamp_box(l, view)).collect();
        // Rows whose centres (y + ½) a box reaches.
        let mut rows = (h, 0);
        for b in &boxes {
            let (y0, y1) = b.map_or((0, h), |[_, y0, _, y1]| {
                let first = (y0 - 0.5).ceil().clamp(0.0, h as f64) as usize;
                let end = ((y1 - 0.5).floor() + 1.0).clamp(0.0, h as f64) as usize;
                (first, end)
            });
            if y0 < y1 {
                rows = (rows.0.min(y0), rows.1.max(y1));
            }
        }
        if rows.0 >= rows.1 {
            return (0, Vec::new());
        }
        let seen = (rows.0 * w..rows.1 * w)
            .into_par_iter()
            .map(|i| {
                let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                let may = |k: usize| {
                    boxes[k].is_none_or(|[x0, y0, x1, y1]| x >= x0 && x <= x1 && y >= y0 && y <= y1)
                };
                if !(0..lights.len()).any(may) {
                    return None;
                }
                let d = view.ray_dir(x, y);
                let (t, l, q) = lights
                    .iter()
                    .enumerate()
                    .filter(|&(k, _)| may(k))
                    .filter_map(|(_, l)| l.hit(view.eye, d).map(|(t, q)| (t, l, q)))
                    .min_by(|a, b| a.0.total_cmp(&b.0))?;
                // Only a pixel that sees a lamp asks for its surface (most see none). A lamp
                // flush with the surface behind it (an asset's emitting triangles on a
                // ceiling) is in front of it.
                let surface = g
                    .surface(mesh, view, i)
                    .map_or(f64::INFINITY, |s| (s.position - view.eye).length());
                if t > surface * (1.0 + 1e-6) {
                    return None;
                }
                let c = match l.shape {
                    crate::light::Shape::Polygon => l.radiance_at(q),
                    // A spot's bulb is seen lit from inside its cone only.
                    _ => l.radiance_toward(view.eye),
                };
                c.is_finite().then(|| c.as_vec3().to_array())
            })
            .collect();
        (rows.0 * w, seen)
    }

    /// Draws the lamps over a frame ([`Self::emitters`]). Every method's frame goes through
    /// it ([`crate::method::sequence`], the session; a window's GPU frame gets them in its
    /// overlay layer).
    pub fn draw_emitters(&self, img: &mut Image, lights: &[Light]) {
        if lights.is_empty() || img.pixels.len() != self.gbuffer.tri.len() {
            return;
        }
        let (start, seen) = self.emitters_in_rows(lights);
        for (px, e) in img.pixels[start..].iter_mut().zip(seen) {
            if let Some(c) = e {
                *px = c;
            }
        }
    }

    /// Interpolates per-vertex colours over the visible triangles.
    pub(crate) fn interpolate(&self, colour: &[[f32; 3]]) -> Image {
        let mesh = &self.scene.mesh;
        let g = &self.gbuffer;
        let mut img = Image::new(g.width, g.height);
        img.pixels
            .par_iter_mut()
            .zip(g.tri.par_iter().zip(g.bary.par_iter()))
            .for_each(|(px, (&t, &[b1, b2]))| {
                if t == NONE {
                    return;
                }
                let [a, b, c] = mesh.triangles[t as usize].map(|v| colour[v as usize]);
                let b0 = 1.0 - b1 - b2;
                *px = std::array::from_fn(|k| b0 * a[k] + b1 * b[k] + b2 * c[k]);
            });
        img
    }

    /// Every covered pixel that faces the viewer, with its surface, the unit direction to the
    /// eye and its material (textures looked up at its UV): `shade` gives its radiance (`None`
    /// leaves it black). The one per-pixel loop of the LTC, sky and punctual shaders.
    fn per_surface(
        &self,
        shade: impl Fn(&Surface, DVec3, &Material) -> Option<DVec3> + Sync,
    ) -> Image {
        let mesh = &self.scene.mesh;
        let g = &self.gbuffer;
        let mut img = Image::new(g.width, g.height);
        img.pixels.par_iter_mut().enumerate().for_each(|(i, px)| {
            let Some(s) = g.surface(mesh, &self.view, i) else {
                return;
            };
            let wo = (self.view.eye - s.position).normalize_or(s.normal);
            if !crate::shade::sees_viewer(s.normal, wo) {
                return;
            }
            let id = mesh.material_ids.get(s.tri as usize).copied().unwrap_or(0);
            let m = self.material_footprint(id, mesh.uv_at(s.tri as usize, s.weights), s.duv);
            if let Some(c) = shade(&s, wo, &m) {
                *px = c.as_vec3().to_array();
            }
        });
        img
    }

    /// Per-vertex shadow ratios `r` interpolated at surface `s`.
    fn ratio_at(&self, r: &[ShadowRatio], s: &Surface) -> ShadowRatio {
        let idx = self.scene.mesh.triangles[s.tri as usize];
        let w = s.weights;
        let f = |lobe: usize, c: usize| {
            (w[0] * f64::from(r[idx[0] as usize][lobe][c])
                + w[1] * f64::from(r[idx[1] as usize][lobe][c])
                + w[2] * f64::from(r[idx[2] as usize][lobe][c])) as f32
        };
        [0, 1].map(|lobe| [0, 1, 2].map(|c| f(lobe, c)))
    }

    /// Shades every covered pixel with `shade(lobes, p, n, ratio)`, `ratio` the per-vertex
    /// shadow ratios interpolated at the pixel ([`UNSHADOWED`] without).
    fn per_pixel(
        &self,
        ratio: Option<&[ShadowRatio]>,
        shade: impl Fn(&Lobes, DVec3, DVec3, ShadowRatio) -> DVec3 + Sync,
    ) -> Image {
        self.per_surface(|s, wo, m| {
            let lobes = Lobes::new(self.table, m, s.normal, wo);
            let r = ratio.map_or(UNSHADOWED, |r| self.ratio_at(r, s));
            Some(shade(&lobes, s.position, s.normal, r))
        })
    }

    /// A punctual light's unshadowed radiance per pixel (KHR_lights_punctual): the exact BRDF
    /// at the pixel's material (textures looked up) times the light's intensity, its spot and
    /// range falloff, and 1 / d² — a point light is a delta, there is nothing to integrate.
    pub(crate) fn shade_pixels_punctual(&self, light: &bspvt_proto::scene::PunctualLight) -> Image {
        let pos = glam::Vec3::from(light.position).as_dvec3();
        let intensity = glam::Vec3::from(light.intensity).as_dvec3();
        self.per_surface(|s, wo, m| {
            let to = pos - s.position;
            let d2 = to.length_squared();
            if !(d2 > 0.0) || !d2.is_finite() {
                return None;
            }
            let wi = to / d2.sqrt();
            let falloff = f64::from(light.falloff(s.position.as_vec3()));
            if !(falloff > 0.0) {
                return None;
            }
            let brdf = crate::frame::brdf::Brdf::from_material(m);
            let frame = crate::frame::shading::ShadingFrame::new(s.normal, wo);
            let f = brdf.eval_cos(frame.to_local(wo), frame.to_local(wi));
            let c = f * intensity * (falloff / d2);
            c.is_finite().then_some(c)
        })
    }

    /// Per-pixel LTC of `lights`, each times its own per-vertex shadow ratios interpolated
    /// (`ratios[l]`; `None`: unshadowed): Σ_l L_l ⊙ (albedo·D_l·r_l,d + spec·S_l·r_l,s).
    pub fn shade_pixels(&self, lights: &[Light], ratios: Option<&[Vec<ShadowRatio>]>) -> Image {
        self.per_surface(|s, wo, m| {
            let lobes = Lobes::new(self.table, m, s.normal, wo);
            let mut c = DVec3::ZERO;
            for (l, light) in lights.iter().enumerate() {
                let i = unshadowed(&lobes, light, s.position, s.normal);
                if i.integrals.diffuse <= 0.0 && i.integrals.specular <= 0.0 {
                    continue;
                }
                let r = match ratios.and_then(|r| r.get(l)) {
                    Some(r) => self.ratio_at(r, s),
                    None => UNSHADOWED,
                };
                c += lobes.radiance_scaled(light.radiance_toward(s.position), &i, r);
            }
            Some(c)
        })
    }

    /// The unshadowed sky per pixel times interpolated sky shadow ratios.
    pub(crate) fn shade_pixels_sky(
        &self,
        pieces: &[Light],
        ratio: Option<&[ShadowRatio]>,
    ) -> Image {
        self.per_pixel(ratio, |lobes, _, n, r| {
            let s = unshadowed_sky(lobes, pieces, n);
            lobes.radiance_scaled(DVec3::ONE, &s, r)
        })
    }

    /// One frame of the sky through the baked sky trees in `mode` (`trees`: `None` while none
    /// have arrived: unshadowed).
    pub fn sky(&self, pieces: &[Light], trees: Option<&Trees>, mode: Mode) -> (Image, FrameCounts) {
        let (colour, ratio, mut counts) =
            self.shade_vertices_sky(pieces, trees, mode == Mode::Pixel);
        match mode {
            Mode::Vertex => (self.interpolate(&colour), counts),
            Mode::Pixel => {
                counts.pixels_shaded = self.gbuffer.covered();
                (self.shade_pixels_sky(pieces, Some(&ratio)), counts)
            }
        }
    }

    /// One BSPVT frame of `lights` in `mode`.
    pub fn bspvt(&self, lights: &[Light], trees: &Trees, mode: Mode) -> (Image, FrameCounts) {
        let (colour, ratios, mut counts) = self.shade_vertices(lights, trees, mode == Mode::Pixel);
        match mode {
            Mode::Vertex => (self.interpolate(&colour), counts),
            Mode::Pixel => {
                counts.pixels_shaded = self.gbuffer.covered();
                (self.shade_pixels(lights, Some(&ratios)), counts)
            }
        }
    }

    /// BSPVT of `lights`, each through the trees that hold it: where the scene bakes its suns
    /// apart ([`Scene::suns_in_sky_bake`]) the suns through the sky's trees `sky`, the others
    /// through `trees`; else all through `trees`. Lights whose trees have not arrived (`None`)
    /// are shaded unshadowed.
    pub fn bspvt_lights(
        &self,
        lights: &[Light],
        trees: Option<&Trees>,
        sky: Option<&Trees>,
        mode: Mode,
    ) -> (Image, FrameCounts) {
        let one = |ls: &[Light], t: Option<&Trees>| match t {
            Some(t) => self.bspvt(ls, t, mode),
            None => self.ltc(ls, mode),
        };
        if !self.scene.suns_in_sky_bake() {
            return one(lights, trees);
        }
        let (suns, rest): (Vec<Light>, Vec<Light>) = lights
            .iter()
            .cloned()
            .partition(|l| matches!(l.shape, crate::light::Shape::Distant { .. }));
        match (rest.is_empty(), suns.is_empty()) {
            (_, true) => one(&rest, trees),
            (true, false) => one(&suns, sky),
            (false, false) => {
                let (mut image, mut counts) = one(&rest, trees);
                let (sun, c) = one(&suns, sky);
                image.add(&sun);
                counts.pieces += c.pieces;
                counts.pieces_dropped += c.pieces_dropped;
                (image, counts)
            }
        }
    }

    /// One unshadowed-LTC frame of `lights` in `mode`.
    pub fn ltc(&self, lights: &[Light], mode: Mode) -> (Image, FrameCounts) {
        match mode {
            Mode::Vertex => (
                self.interpolate(&self.shade_vertices_unshadowed(lights)),
                FrameCounts {
                    vertices_shaded: self.visible_vertices.len(),
                    ..FrameCounts::default()
                },
            ),
            Mode::Pixel => (
                self.shade_pixels(lights, None),
                FrameCounts {
                    pixels_shaded: self.gbuffer.covered(),
                    ..FrameCounts::default()
                },
            ),
        }
    }
}

/// The vertices of the triangles `g` sees, and per vertex whether it is seen from behind
/// ([`GBuffer::vertex_sides`]).
fn seen(g: &GBuffer, mesh: &bspvt_proto::Mesh, eye: DVec3) -> (Vec<u32>, Vec<bool>) {
    let (seen, behind) = g.vertex_sides(mesh, eye);
    let visible = seen
        .iter()
        .enumerate()
        .filter_map(|(v, &s)| s.then_some(v as u32))
        .collect();
    (visible, behind)
}

/// Where a polygon lamp wholly in front of the eye can be seen: the box [x0, y0, x1, y1] of its
/// corners' images, a pixel wider for rounding (a planar polygon in front of the eye projects
/// into the convex hull of its corners' images); `None` (every pixel) for bulbs, suns and a
/// polygon reaching behind the eye. [`Renderer::emitters`] traces no pixel outside it.
fn lamp_box(l: &Light, view: &View) -> Option<[f64; 4]> {
    if !matches!(l.shape, crate::light::Shape::Polygon) {
        return None;
    }
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for &v in &l.vertices {
        let c = view.to_camera(v);
        if !(c.z > 0.0) {
            return None;
        }
        let (x, y) = view.to_image(c);
        b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
    }
    b.iter()
        .all(|x| x.is_finite())
        .then(|| [b[0] - 1.0, b[1] - 1.0, b[2] + 1.0, b[3] + 1.0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use bspvt_proto::scene::PolygonLight;

    /// The lamps as the camera sees them are the same with the boxes as tracing every pixel
    /// toward every lamp: two quads in view (one one-sided), one reaching behind the eye, one
    /// off screen, a small one, and the scene's own; then the boxed ones alone, whose rows are
    /// fewer than the image's.
    #[test]
    fn lamps_seen_are_those_every_pixel_would_find() {
        let scene = bspvt_proto::builtin::scene("plate-small").expect("built-in scene");
        let r = Renderer::new(&scene, 96, 64);
        let (eye, at) = (r.view.eye, scene.camera.target);
        let at = glam::Vec3::from(at).as_dvec3();
        let fwd = (at - eye).normalize();
        let side = fwd.cross(glam::DVec3::Y).normalize();
        let up = side.cross(fwd);
        let tilted = |c: glam::DVec3, s: f64, two_sided: bool, v: glam::DVec3| {
            let corner = |a: f64, b: f64| (c + s * (a * side + b * v)).as_vec3().to_array();
            Light::load(&PolygonLight {
                vertices: vec![
                    corner(-1.0, -1.0),
                    corner(-1.0, 1.0),
                    corner(1.0, 1.0),
                    corner(1.0, -1.0),
                ],
                radiance: [1.0, 2.0, 3.0],
                two_sided,
                texture: None,
                region: None,
                moves_in_plane: false,
                image: None,
            })
            .expect("a lamp")
        };
        let quad = |c, s, two_sided| tilted(c, s, two_sided, up);
        let mid = eye + 0.5 * (at - eye);
        let mut lights = vec![
            quad(mid, 0.1 * (at - eye).length(), true),
            quad(mid + 0.05 * side, 0.08 * (at - eye).length(), false),
            // A floor under the eye running from behind it to ahead of it.
            tilted(eye - 0.2 * up, 0.5, true, fwd),
            quad(eye + fwd - 3.0 * side, 0.1, true),
            quad(mid - 0.1 * up, 0.02 * (at - eye).length(), true),
        ];
        lights.extend(
            crate::light::scene_lights(&scene)
                .expect("lights")
                .into_iter()
                .map(|(l, _)| l),
        );
        assert!(lamp_box(&lights[0], &r.view).is_some());
        assert!(
            lamp_box(&lights[2], &r.view).is_none(),
            "reaches behind the eye"
        );
        let w = r.gbuffer.width as usize;
        // Every lamp (one box is the whole image), then the boxed ones alone (their rows).
        let boxed: Vec<Light> = [3, 4].map(|k| lights[k].clone()).into();
        let (start, rows) = r.emitters_in_rows(&boxed);
        assert!(
            start > 0 && start + rows.len() < w * 64,
            "the small lamp's rows: {start} + {}",
            rows.len()
        );
        for lights in [&lights[..], &boxed[..]] {
            let got = r.emitters(lights);
            let mut drawn = crate::frame::image::Image::new(96, 64);
            r.draw_emitters(&mut drawn, lights);
            let mut seen = 0;
            for (i, e) in got.iter().enumerate() {
                let d = r.view.ray_dir((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
                let every = lights
                    .iter()
                    .filter_map(|l| l.hit(r.view.eye, d).map(|(t, q)| (t, l, q)))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .filter(|&(t, _, _)| {
                        let s = r
                            .gbuffer
                            .surface(&scene.mesh, &r.view, i)
                            .map_or(f64::INFINITY, |s| (s.position - r.view.eye).length());
                        t <= s * (1.0 + 1e-6)
                    })
                    .map(|(_, l, q)| l.radiance_at(q).as_vec3().to_array());
                assert_eq!(*e, every, "pixel {i}");
                assert_eq!(drawn.pixels[i], e.unwrap_or_default(), "pixel {i} drawn");
                seen += usize::from(e.is_some());
            }
            assert!(seen > 10, "{seen} pixels see a lamp");
        }
    }
}
