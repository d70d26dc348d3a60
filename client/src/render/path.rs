//! The light's motion over an animation: a circle through the light's declared region (or
//! around its rest position, for a light that moves in its plane) with a rocking rotation
//! about a horizontal axis through its centre — translate + rotate, as the paper's interactive
//! demo allows. A fixed lamp stays where it is (its bake holds for that place only); a sun
//! turns once about the vertical (its bake holds every direction).

use glam::{DAffine3, DQuat, DVec3};

use crate::light::Light;
use bspvt_proto::scene::LightMotion;

/// The light's default motion: around a horizontal circle, turning as it goes.
#[derive(Clone, Debug)]
pub struct LightPath {
    base: Light,
    centre: DVec3,
    /// Circle centre and radius (horizontal plane through the light).
    orbit_centre: DVec3,
    radius: f64,
    /// Peak rotation in radians.
    tilt: f64,
    /// Turns once about the vertical (a sun).
    turns: bool,
}

impl LightPath {
    /// The default path of a scene light: a circle of 35 % of the region's smaller horizontal
    /// extent (or of the light's own size when it moves in its plane), tilting ±20°; a fixed
    /// lamp's path is its place; a sun turns once about the vertical. `base`: the scene light
    /// as loaded ([`crate::light::scene_lights`], with its texture); `motion`: where its bake
    /// lets it go.
    pub fn new(motion: LightMotion, base: Light) -> LightPath {
        let centre = base.centroid();
        let still = |turns| LightPath {
            base: base.clone(),
            centre,
            orbit_centre: centre,
            radius: 0.0,
            tilt: 0.0,
            turns,
        };
        let region = match motion {
            LightMotion::Fixed => return still(false),
            LightMotion::Turns => return still(true),
            LightMotion::Region(r) => Some(r),
            LightMotion::Plane => None,
        };
        let (orbit_centre, radius) = match &region {
            Some(r) => {
                let (lo, hi) = (
                    glam::Vec3::from(r.min).as_dvec3(),
                    glam::Vec3::from(r.max).as_dvec3(),
                );
                let c = 0.5 * (lo + hi);
                (
                    DVec3::new(c.x, centre.y, c.z),
                    0.35 * (hi.x - lo.x).min(hi.z - lo.z),
                )
            }
            None => {
                let size = base
                    .vertices
                    .iter()
                    .map(|v| (*v - centre).length())
                    .fold(0.0, f64::max);
                (centre, size)
            }
        };
        LightPath {
            base,
            centre,
            orbit_centre,
            radius,
            tilt: 20f64.to_radians(),
            turns: false,
        }
    }

    /// The light at animation time `t` ∈ [0, 1).
    pub fn at(&self, t: f64) -> Light {
        let phase = std::f64::consts::TAU * t;
        if self.turns {
            return self
                .base
                .transformed(&DAffine3::from_quat(DQuat::from_rotation_y(phase)));
        }
        let target = self.orbit_centre + self.radius * DVec3::new(phase.cos(), 0.0, phase.sin());
        let rot = DQuat::from_axis_angle(DVec3::X, self.tilt * phase.sin());
        let m = DAffine3::from_translation(target)
            * DAffine3::from_quat(rot)
            * DAffine3::from_translation(-self.centre);
        self.base.transformed(&m)
    }

    /// Frame `k` of `n`.
    pub fn frame(&self, k: usize, n: usize) -> Light {
        self.at(k as f64 / n.max(1) as f64)
    }
}
