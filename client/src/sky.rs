//! The environment map as polygonal lights at infinity, for shading through the baked trees
//! (the BSPVT authors' viewer lights its scenes the same way).
//!
//! Each face of the world-aligned cube around the origin is cut into k×k squares; a square is
//! a planar quad on the unit cube, i.e. a spherical quad of directions, lit by a textured quad
//! light whose texture is the map resampled on the square's gnomonic grid (texel value = mean
//! radiance over the texel's directions) and prefiltered as any light texture
//! ([`crate::texture`], Heitz et al. 2016 §5.3). Seen from a shading point the pieces lie at
//! infinity: their directions do not depend on the point, so they are shaded from the origin
//! ([`crate::shade::sky`]). The six faces tile the sphere exactly, so a constant map gives the
//! exact cosine and LTC integrals over the hemisphere.
//!
//! Rotating the map about +y only moves the pieces' corners ([`SkyPieces::posed`]); the
//! textures stay, and so do the trees.

use std::sync::Arc;

use anyhow::{Result, bail};
use bspvt_proto::cubemap::{FACES, FaceFrame};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::envmap::EnvLight;
use crate::frame::stats::luminance;
use crate::light::Light;
use crate::texture::LightTexture;

/// Default pieces per cube-face side (chosen by measured error: docs/benchmarks.md,
/// "Environment lighting through the trees").
pub const DEFAULT_K: u32 = 2;
/// Largest k accepted (6·k² pieces).
pub const MAX_K: u32 = 32;
/// Pieces carrying less than this fraction of the map's power (luminance × solid angle) are
/// left out.
pub const DEFAULT_THRESHOLD: f64 = 1e-4;

/// Texels per side of a piece's texture: about the map's own resolution on the cube (a face
/// spans a quarter of the map's width), within [4, 128].
fn texture_side(env: &EnvLight, k: u32) -> usize {
    (env.height as usize / (2 * k as usize)).clamp(4, 128)
}

/// Sub-samples per texel side when resampling the map.
const SUPERSAMPLE: usize = 3;

/// One piece at rest: its corners on the unit cube and its prefiltered texture.
#[derive(Clone, Debug)]
struct Piece {
    corners: [DVec3; 4],
    texture: Arc<LightTexture>,
    /// Solid angle (sr).
    solid_angle: f64,
}

/// The environment as pieces (see the module doc).
#[derive(Clone, Debug)]
pub struct SkyPieces {
    pieces: Vec<Piece>,
    /// Pieces per face side.
    pub k: u32,
    /// Pieces left out as negligible.
    pub dropped: usize,
    /// The fraction of the map's power they carried.
    pub dropped_power: f64,
    /// The map's radiance scale.
    pub strength: f64,
    /// Whether a piece was split for its power more than [`SUN_DEPTH`] times: a small bright
    /// source (a sun), ≥ 16× the map's mean radiance over 1/16 of a piece.
    pub has_sun: bool,
}

impl SkyPieces {
    /// Cuts `env` into 6·k² pieces, leaving out those carrying less than `threshold` of the
    /// map's power. `strength` scales the radiance.
    pub fn new(env: &EnvLight, k: u32, threshold: f64, strength: f64) -> Result<SkyPieces> {
        if !(1..=MAX_K).contains(&k) {
            bail!("pieces per face side must be in 1..={MAX_K}, not {k}");
        }
        if !(threshold.is_finite() && (0.0..1.0).contains(&threshold)) {
            bail!("the negligible-piece threshold must be in [0, 1), not {threshold}");
        }
        if !(strength.is_finite() && strength >= 0.0) {
            bail!("the environment strength must be finite and ≥ 0, not {strength}");
        }
        let step = 2.0 / f64::from(k);
        let cells: Vec<Cell> = (0..FACES)
            .flat_map(|f| {
                (0..k).flat_map(move |j| {
                    (0..k).map(move |i| Cell {
                        face: f,
                        s0: -1.0 + step * f64::from(i),
                        t0: -1.0 + step * f64::from(j),
                        step,
                        depth: 0,
                    })
                })
            })
            .collect();
        let side = texture_side(env, k);
        let mut built: Vec<(Piece, f64, Cell)> = cells
            .par_iter()
            .map(|&c| piece(env, c, side).map(|(p, w)| (p, w, c)))
            .collect::<Result<_>>()?;
        let total: f64 = built.iter().map(|(_, p, _)| p).sum();
        // Pieces holding much more than an even share of the power (a sun) and brighter than
        // the map on average are split into 2×2 until they are not, so that a small bright
        // source is as small as it is: one texture fetch per tree piece cannot place it
        // within a large piece. A piece whose texture varies across it (a horizon) is split
        // once too (SPLIT_VARIATION). A constant map is never split.
        let share = SPLIT_SHARE / (FACES as f64 * f64::from(k * k));
        let omega: f64 = built.iter().map(|(p, _, _)| p.solid_angle).sum();
        let mean = total / omega.max(1e-300);
        let mut has_sun = false;
        loop {
            let (split, keep): (Vec<_>, Vec<_>) = built.into_iter().partition(|(p, w, c)| {
                let sun = *w > share * total
                    && *w > SPLIT_CONTRAST * mean * p.solid_angle
                    && c.depth < MAX_SPLIT_DEPTH;
                // Split twice already and still over an even share: ≥ 16× the map's mean.
                has_sun |= total > 0.0 && sun && c.depth >= SUN_DEPTH;
                let varied = c.depth < MAX_VARIATION_DEPTH
                    && *w > VARIATION_SHARE * share * total
                    && crate::texture::quadrant_variation(&p.texture) > SPLIT_VARIATION;
                total > 0.0 && (sun || varied)
            });
            built = keep;
            if split.is_empty() {
                break;
            }
            let children: Vec<Cell> = split.iter().flat_map(|(_, _, c)| c.children()).collect();
            let more: Vec<(Piece, f64, Cell)> = children
                .par_iter()
                .map(|&c| {
                    let n = (side >> c.depth).max(MIN_TEXTURE_SIDE);
                    piece(env, c, n).map(|(p, w)| (p, w, c))
                })
                .collect::<Result<_>>()?;
            built.extend(more);
        }
        let mut pieces = Vec::with_capacity(built.len());
        let (mut dropped, mut dropped_power) = (0, 0.0);
        for (p, power, _) in built {
            if total > 0.0 && power < threshold * total {
                dropped += 1;
                dropped_power += power / total;
            } else if total > 0.0 {
                pieces.push(p);
            }
        }
        Ok(SkyPieces {
            pieces,
            k,
            dropped,
            dropped_power,
            strength,
            has_sun,
        })
    }

    /// Pieces kept.
    pub fn len(&self) -> usize {
        self.pieces.len()
    }

    /// True when the map is black (nothing to shade).
    pub fn is_empty(&self) -> bool {
        self.pieces.is_empty()
    }

    /// The pieces as lights at infinity for the map turned by `rotation_deg` about +y: corners
    /// are directions (shade them from the origin), two-sided.
    pub fn posed(&self, rotation_deg: f64) -> Vec<Light> {
        let r = DMat3::from_rotation_y(rotation_deg.to_radians());
        self.pieces
            .iter()
            .map(|p| {
                let vertices: Vec<DVec3> = p.corners.iter().map(|&c| r * c).collect();
                let normal = (vertices[1] - vertices[0])
                    .cross(vertices[3] - vertices[0])
                    .normalize_or(DVec3::Y);
                Light {
                    vertices,
                    normal,
                    radiance: DVec3::splat(self.strength),
                    two_sided: true,
                    texture: Some(p.texture.clone()),
                    shape: crate::light::Shape::Polygon,
                }
            })
            .collect()
    }
}

/// A square of a cube face: face coordinates [s₀, s₀ + step] × [t₀, t₀ + step].
#[derive(Clone, Copy, Debug)]
struct Cell {
    face: usize,
    s0: f64,
    t0: f64,
    step: f64,
    depth: u32,
}

impl Cell {
    fn children(&self) -> [Cell; 4] {
        let h = self.step / 2.0;
        [(0.0, 0.0), (h, 0.0), (0.0, h), (h, h)].map(|(ds, dt)| Cell {
            face: self.face,
            s0: self.s0 + ds,
            t0: self.t0 + dt,
            step: h,
            depth: self.depth + 1,
        })
    }
}

/// A piece is split while it holds more than this many even shares of the map's power…
const SPLIT_SHARE: f64 = 1.0;
/// … and its mean radiance is more than this many times the map's (a margin above 1, so
/// that a constant map is not split by rounding).
const SPLIT_CONTRAST: f64 = 1.1;
/// A piece split for its power this many times and still split is a sun
/// ([`SkyPieces::has_sun`]).
const SUN_DEPTH: u32 = 2;
/// Splits of a piece at most (a piece of side 2/k is split down to 2/(k·2⁵)).
const MAX_SPLIT_DEPTH: u32 = 5;
/// A piece whose quadrants' mean luminances differ by more than this fraction of its mean (a
/// horizon, a skyline) is split 2×2 too, at most [`MAX_VARIATION_DEPTH`] times, when it holds
/// at least [`VARIATION_SHARE`] of an even share of the power: a tree piece seen through a
/// doorway reads one filtered texel of its piece, and a sky-and-ground piece has none that
/// fits both halves.
const SPLIT_VARIATION: f64 = 0.5;
const MAX_VARIATION_DEPTH: u32 = 1;
const VARIATION_SHARE: f64 = 0.25;
/// Smallest texture side of a split piece.
const MIN_TEXTURE_SIDE: usize = 4;

/// The piece of `cell`, with an n×n texture: corners ordered so that the light texture's
/// (u, v) basis (p₁ − p₀, p₃ − p₀) runs along the face's a and b axes; texel (x, y) is the
/// mean of the map over SUPERSAMPLE² directions through its square. Returns the piece and
/// its power (luminance × solid angle, for splitting and leaving out).
fn piece(env: &EnvLight, cell: Cell, n: usize) -> Result<(Piece, f64)> {
    let fr = FaceFrame::of(cell.face);
    let (w, a, b) = (fr.w64(), fr.a64(), fr.b64());
    let Cell { s0, t0, step, .. } = cell;
    let at = |s: f64, t: f64| w + a * s + b * t;
    let corners = [
        at(s0, t0),
        at(s0 + step, t0),
        at(s0 + step, t0 + step),
        at(s0, t0 + step),
    ];
    let texel = step / n as f64;
    let sub = texel / SUPERSAMPLE as f64;
    let mut texels = Vec::with_capacity(n * n);
    let (mut power, mut solid_angle) = (0.0, 0.0);
    for y in 0..n {
        for x in 0..n {
            let mut c = DVec3::ZERO;
            for sy in 0..SUPERSAMPLE {
                for sx in 0..SUPERSAMPLE {
                    let s = s0 + texel * x as f64 + sub * (sx as f64 + 0.5);
                    let t = t0 + texel * y as f64 + sub * (sy as f64 + 0.5);
                    c += env.eval(at(s, t));
                }
            }
            let c = c / (SUPERSAMPLE * SUPERSAMPLE) as f64;
            // Solid angle of the texel: dA / (1 + s² + t²)^{3/2} at its centre.
            let (s, t) = (s0 + texel * (x as f64 + 0.5), t0 + texel * (y as f64 + 0.5));
            let omega = texel * texel / (1.0 + s * s + t * t).powf(1.5);
            power += luminance(c.x, c.y, c.z) * omega;
            solid_angle += omega;
            texels.push(c.as_vec3().to_array());
        }
    }
    let texture = Arc::new(LightTexture::from_texels(n, n, &texels)?);
    Ok((
        Piece {
            corners,
            texture,
            solid_angle,
        },
        power,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_tile_the_sphere_and_carry_the_map() {
        let env = EnvLight::constant([1.0, 1.0, 1.0]);
        for k in [1, 2, 3] {
            let s = SkyPieces::new(&env, k, DEFAULT_THRESHOLD, 1.0).expect("pieces");
            assert_eq!(s.len(), 6 * (k * k) as usize);
            assert_eq!(s.dropped, 0);
            // Solid angles of the pieces sum to 4π (each piece is a spherical quad).
            let total: f64 = s
                .posed(37.0)
                .iter()
                .map(|l| {
                    let d: Vec<DVec3> = l.vertices.iter().map(|v| v.normalize()).collect();
                    bspvt_proto::sphere::solid_angle(&d)
                })
                .sum();
            assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-9, "{total}");
        }
        assert!(SkyPieces::new(&env, 0, DEFAULT_THRESHOLD, 1.0).is_err());
        assert!(SkyPieces::new(&env, 2, f64::NAN, 1.0).is_err());
        assert!(SkyPieces::new(&env, 2, 0.0, -1.0).is_err());
    }

    /// A small bright source makes a sun; a smooth sky (brighter up than down, ×20) does not.
    #[test]
    fn a_sun_is_told_from_a_bright_sky() {
        let dir = tempfile::tempdir().expect("temp dir");
        let env = EnvLight::load(&crate::envmap::write_test_map(dir.path())).expect("map");
        let s = SkyPieces::new(&env, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
        assert!(s.has_sun, "the test map's 6×6-texel sun at 100× the sky");
        let (w, h) = (64u32, 32u32);
        let px = (0..w * h)
            .map(|i| [1.0 + 19.0 * (1.0 - (i / w) as f32 / h as f32); 3])
            .collect();
        let sky = EnvLight::from_pixels(w, h, px).expect("map");
        let s = SkyPieces::new(&sky, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
        assert!(!s.has_sun);
    }

    #[test]
    fn black_pieces_are_left_out() {
        // Upper half bright, lower half black: the −y face and the lower halves go.
        let (w, h) = (64u32, 32u32);
        let px = (0..w * h)
            .map(|i| if i / w < h / 2 { [1.0; 3] } else { [0.0; 3] })
            .collect();
        let env = EnvLight::from_pixels(w, h, px).expect("map");
        let s = SkyPieces::new(&env, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
        assert!(s.dropped >= 4, "dropped {}", s.dropped);
        assert!(s.dropped_power < DEFAULT_THRESHOLD * s.dropped as f64 + 1e-12);
        let black = EnvLight::from_pixels(w, h, vec![[0.0; 3]; (w * h) as usize]).expect("map");
        assert!(
            SkyPieces::new(&black, 2, 0.0, 1.0)
                .expect("pieces")
                .is_empty()
        );
    }

    use crate::frame::shading::ShadingFrame;
    use crate::ltc::table::LtcTable;
    use crate::render::renderer::{Mode, Renderer, Trees};
    use bspvt_proto::Scene;
    use bspvt_proto::encoding::{Bake, decode_bake};
    use bspvt_proto::scene::{BakeSettings, Camera, Material};

    /// An open plane facing +y, lit by the sky alone, and its sky bake.
    fn open_plane(material: Material) -> (Scene, Bake) {
        let mesh = bspvt_proto::builtin::grid_plane(
            glam::Vec3::ZERO,
            glam::Vec3::X,
            glam::Vec3::NEG_Z,
            5,
            0,
        );
        let scene = Scene {
            mesh,
            materials: vec![material],
            lights: Vec::new(),
            environment: None,
            camera: Camera {
                position: [0.3, 2.0, 2.5],
                target: [0.0, 0.0, 0.0],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: 50.0,
                aspect: None,
            },
            bake: BakeSettings {
                face_res: 16,
                ..BakeSettings::default()
            },
            motion: Vec::new(),
            warnings: Vec::new(),
            punctual: Vec::new(),
            suns: Vec::new(),
        };
        scene.validate().expect("valid scene");
        let out = bspvt_bake::Baker::new(&scene)
            .bake_all(&|_, _| {}, &std::sync::atomic::AtomicBool::new(false))
            .expect("bake");
        let bake = decode_bake(&out.bytes).expect("decode");
        (scene, bake)
    }

    /// A material of albedo (0.6, 0.5, 0.4), roughness `alpha` and grey F0 `f0`.
    fn plastic(alpha: f32, f0: f32) -> Material {
        Material {
            name: "m".into(),
            roughness: alpha,
            albedo: [0.6, 0.5, 0.4],
            specular: [f0; 3],
            maps: None,
            cutout: None,
            normal_map: None,
        }
    }

    /// ∫ over the upper hemisphere of the LTC density: midpoint rule in (cos θ, φ).
    fn ltc_hemisphere(ltc: &crate::ltc::table::Ltc) -> f64 {
        let (nu, nphi) = (800, 800);
        let mut sum = 0.0;
        for i in 0..nu {
            let z = (i as f64 + 0.5) / nu as f64;
            let r = (1.0 - z * z).sqrt();
            for j in 0..nphi {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / nphi as f64;
                sum += ltc.density(DVec3::new(r * phi.cos(), r * phi.sin(), z));
            }
        }
        sum * 2.0 * std::f64::consts::PI / (nu * nphi) as f64
    }

    /// A white furnace through the trees: a constant map of radiance 1 over an open plane
    /// gives, per vertex, albedo · 1 (∫ cos/π over the hemisphere) plus the LTC albedo
    /// (F0 · magnitude + (1 − F0) · fresnel) · ∫_H D_ltc, the latter by quadrature.
    #[test]
    fn white_sky_over_an_open_plane_is_the_furnace() {
        let env = EnvLight::constant([1.0, 1.0, 1.0]);
        for (alpha, k) in [(0.05f32, 1), (0.3, 2), (0.8, 3)] {
            let m = Material {
                name: "m".into(),
                roughness: alpha,
                albedo: [0.5, 0.5, 0.5],
                specular: [0.04; 3],
                maps: None,
                cutout: None,
                normal_map: None,
            };
            let (scene, bake) = open_plane(m.clone());
            let trees = Trees::full(&bake.trees, bake.header.codec());
            let pieces = SkyPieces::new(&env, k, DEFAULT_THRESHOLD, 1.0)
                .expect("pieces")
                .posed(10.0);
            let r = Renderer::new(&scene, 64, 64);
            let (colour, ratio, counts) = r.shade_vertices_sky(&pieces, Some(&trees), true);
            assert!(counts.vertices_shaded > 10);
            let table = LtcTable::builtin();
            let mut worst = 0.0f64;
            for &v in &r.visible_vertices {
                let p = scene.mesh.positions[v as usize].as_dvec3();
                let wo = (r.view.eye - p).normalize();
                let n = DVec3::Y;
                let ltc = table.lookup(
                    crate::ggx::clamp_alpha(f64::from(alpha)),
                    ShadingFrame::new(n, wo).cos_view(wo),
                );
                let spec = 0.04 * ltc.magnitude + 0.96 * ltc.fresnel;
                let expected = 0.5 + spec * ltc_hemisphere(&ltc);
                let got = f64::from(colour[v as usize][1]);
                worst = worst.max((got - expected).abs() / expected);
                assert_eq!(
                    ratio[v as usize],
                    crate::shade::UNSHADOWED,
                    "an open plane is unshadowed"
                );
            }
            eprintln!("furnace α = {alpha}, k = {k}: worst relative error {worst:.2e}");
            assert!(
                worst < 2e-3,
                "α = {alpha}, k = {k}: relative error {worst:.2e}"
            );
        }
    }

    /// Turning the map by 90° about +y through the pieces equals turning its pixels (a
    /// quarter of its columns): the cube maps onto itself, so the two frames agree to
    /// rounding (texel ties aside).
    #[test]
    fn a_quarter_turn_of_the_pieces_is_a_quarter_turn_of_the_pixels() {
        let dir = tempfile::tempdir().expect("temp dir");
        let env = EnvLight::load(&crate::envmap::write_test_map(dir.path())).expect("map");
        let (w, h) = (env.width as usize, env.height as usize);
        assert_eq!(w % 4, 0);
        // R_y(90°) takes φ = atan2(z, x) to φ − 90°: the result's column x shows the source's
        // column x + w/4.
        let mut px = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                px.push(env.pixels[y * w + (x + w / 4) % w]);
            }
        }
        let turned = EnvLight::from_pixels(env.width, env.height, px).expect("map");
        let (scene, bake) = open_plane(plastic(0.3, 0.04));
        let trees = Trees::full(&bake.trees, bake.header.codec());
        let r = Renderer::new(&scene, 96, 96);
        for mode in [Mode::Vertex, Mode::Pixel] {
            let a = SkyPieces::new(&env, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
            let b = SkyPieces::new(&turned, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
            let (ia, _) = r.sky(&a.posed(90.0), Some(&trees), mode);
            let (ib, _) = r.sky(&b.posed(0.0), Some(&trees), mode);
            let (mut diff, mut sum) = (0.0f64, 0.0f64);
            for (p, q) in ia.pixels.iter().zip(&ib.pixels) {
                for c in 0..3 {
                    diff += f64::from((p[c] - q[c]).abs());
                    sum += f64::from(q[c]);
                }
            }
            assert!(sum > 0.0);
            eprintln!(
                "{mode:?}: quarter turn, mean relative difference {:.2e}",
                diff / sum
            );
            assert!(
                diff / sum < 1e-4,
                "{mode:?}: mean relative difference {:.2e}",
                diff / sum
            );
            // And a turn that is not a symmetry of the cube does change the image.
            let (ic, _) = r.sky(&a.posed(45.0), Some(&trees), mode);
            let moved: f64 = ia
                .pixels
                .iter()
                .zip(&ic.pixels)
                .map(|(p, q)| f64::from((p[1] - q[1]).abs()))
                .sum();
            assert!(moved / sum > 1e-3, "a 45° turn changed nothing");
        }
    }

    /// Mean |a − b| / mean b over the pixels, and the largest |a − b| / max b.
    fn difference(a: &crate::frame::image::Image, b: &crate::frame::image::Image) -> (f64, f64) {
        let (mut diff, mut sum, mut worst, mut top) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (p, q) in a.pixels.iter().zip(&b.pixels) {
            for c in 0..3 {
                let d = f64::from((p[c] - q[c]).abs());
                diff += d;
                sum += f64::from(q[c]);
                worst = worst.max(d);
                top = top.max(f64::from(q[c]));
            }
        }
        assert!(sum > 0.0 && top > 0.0);
        (diff / sum, worst / top)
    }

    /// The sky in world-fixed cells ([`crate::sky_cells`]) against the pieces, per vertex, on
    /// an open plane: a constant map gives the same furnace (both tile the sphere exactly;
    /// ρ = 1); the test map turned by 37° agrees within the cells' resolution, and turned the
    /// other way does not (the cells turn the map the way the pieces do).
    #[test]
    fn cells_turn_the_sky_as_the_pieces_do() {
        use crate::render::sky_cells::CellTransfer;
        use crate::sky_cells::SkyCells;
        let (scene, bake) = open_plane(plastic(0.2, 0.3));
        let trees = Trees::full(&bake.trees, bake.header.codec());
        let r = Renderer::new(&scene, 96, 96);
        let white = EnvLight::constant([1.0, 1.0, 1.0]);
        let cells = SkyCells::new(&white, 12, 1.0).expect("cells");
        let pieces = SkyPieces::new(&white, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
        let (a, counts) = r.sky_cells(
            &cells,
            &cells.radiance(10.0),
            Some(&trees),
            &mut CellTransfer::default(),
        );
        assert!(counts.vertices_shaded > 10);
        let (b, _) = r.sky(&pieces.posed(10.0), Some(&trees), Mode::Vertex);
        let (mean, worst) = difference(&a, &b);
        eprintln!("white sky, cells against pieces: mean {mean:.2e}, worst {worst:.2e}");
        assert!(
            mean < 1e-3 && worst < 3e-3,
            "mean {mean:.2e}, worst {worst:.2e}"
        );

        let dir = tempfile::tempdir().expect("temp dir");
        let env = EnvLight::load(&crate::envmap::write_test_map(dir.path())).expect("map");
        let cells = SkyCells::new(&env, 12, 1.0).expect("cells");
        let pieces = SkyPieces::new(&env, 2, DEFAULT_THRESHOLD, 1.0).expect("pieces");
        let (want, _) = r.sky(&pieces.posed(37.0), Some(&trees), Mode::Vertex);
        let mut keep = CellTransfer::default();
        let (same, _) = r.sky_cells(&cells, &cells.radiance(37.0), Some(&trees), &mut keep);
        let (other, c) = r.sky_cells(&cells, &cells.radiance(-37.0), Some(&trees), &mut keep);
        assert_eq!(c.pieces, 0, "the second frame cut nothing again");
        let (near, _) = difference(&same, &want);
        let (far, _) = difference(&other, &want);
        eprintln!(
            "test map at 37°: cells against pieces {near:.3e}; turned the other way {far:.3e}"
        );
        assert!(near < 0.03, "{near}");
        assert!(far > 3.0 * near, "{far} vs {near}");
    }
}
