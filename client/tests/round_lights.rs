//! Point, spot and sun lights as the polygon-light methods see them (docs/scene-format.md):
//! a sphere of radius r and radiance I / (π r²), the sun a disk of radiance E / Ω, each
//! integrated as a regular spherical polygon of the same solid angle — checked against the
//! closed forms in f64:
//!
//! - a sphere wholly above the horizon: ∫ cos/π dω = sin²α cos θ (α: its angular radius,
//!   θ: its centre's angle from the normal), for LTC and the Monte Carlo;
//! - far away, the irradiance of a point light: E = I cos θ / d²;
//! - the sun: E cos θ at a point whose normal is θ from it, whatever the disk's size (its
//!   radiance is E / (π sin² h), h its half-angle: ∫ cos dω over the cap is π sin² h cos θ);
//! - no NaN or Inf from a point at or inside the sphere, on its surface, or a light at 1e-6
//!   or 1e6 of the scene's size.

use bspvt_client::frame::brdf::{Brdf, Shadows};
use bspvt_client::groundtruth::{Pcg32, ShadingPoint, shade_mc};
use bspvt_client::light::Light;
use bspvt_client::ltc::table::LtcTable;
use bspvt_client::shade::{Lobes, unshadowed};
use bspvt_proto::scene::{Material, PunctualLight, Spot, SunLight};
use glam::DVec3;

fn point_light(position: DVec3, radius: f64, intensity: f32) -> PunctualLight {
    PunctualLight {
        name: "p".into(),
        position: position.as_vec3().to_array(),
        intensity: [intensity; 3],
        range: None,
        spot: None,
        radius: Some(radius as f32),
    }
}

fn diffuse_lobes(n: DVec3) -> Lobes {
    let m = Material {
        roughness: 1.0,
        albedo: [1.0; 3],
        specular: [0.0; 3],
        ..Material::default()
    };
    Lobes::new(LtcTable::builtin(), &m, n, n)
}

/// ∫ cos/π over the light from the origin with normal +z.
fn ltc_diffuse(light: &Light) -> f64 {
    unshadowed(&diffuse_lobes(DVec3::Z), light, DVec3::ZERO, DVec3::Z)
        .integrals
        .diffuse
}

#[test]
fn a_sphere_above_the_horizon_has_lamberts_form_factor() {
    for (theta_deg, d, r) in [
        (0.0, 2.0, 0.5),
        (0.0, 1.2, 1.0),
        (35.0, 3.0, 0.4),
        (60.0, 1.5, 0.3),
        (10.0, 50.0, 0.05),
    ] {
        let t: f64 = f64::to_radians(theta_deg);
        let c = DVec3::new(t.sin(), 0.0, t.cos()) * d;
        let light = Light::sphere(&point_light(c, r, 1.0));
        let sin_a = r / d;
        let want = sin_a * sin_a * t.cos();
        let got = ltc_diffuse(&light);
        let rel = (got - want).abs() / want;
        // The 12-gon has the cap's solid angle; its cosine-weighted area differs at second
        // order in the cap's size.
        assert!(
            rel < 5e-3,
            "θ {theta_deg}° d {d} r {r}: LTC {got} vs {want} ({rel:.2e})"
        );
    }
}

#[test]
fn far_away_a_sphere_gives_a_point_lights_irradiance() {
    let (d, r, i) = (40.0, 0.05, 7.0f32);
    let t = 0.6f64;
    let c = DVec3::new(t.sin(), 0.0, t.cos()) * d;
    let light = Light::sphere(&point_light(c, r, i));
    // E = L ∫ cos dω = L π · (∫ cos/π).
    let e = light.radiance.x * std::f64::consts::PI * ltc_diffuse(&light);
    let want = f64::from(i) * t.cos() / (d * d);
    assert!((e - want).abs() / want < 1e-3, "{e} vs {want}");
}

#[test]
fn the_sun_gives_its_illuminance() {
    for diameter in [0.53f32.to_radians(), 5f32.to_radians(), 0.4] {
        let t = 0.5f64;
        let dir = -DVec3::new(t.sin(), 0.0, t.cos());
        let sun = SunLight {
            name: "sun".into(),
            direction: dir.as_vec3().to_array(),
            illuminance: [3.0; 3],
            angular_diameter: Some(diameter),
        };
        let light = Light::sun(&sun);
        let e = light.radiance.x * std::f64::consts::PI * ltc_diffuse(&light);
        let want = 3.0 * t.cos();
        assert!(
            (e - want).abs() / want < 2e-3,
            "diameter {diameter}: {e} vs {want}"
        );
        // Facing it: the illuminance.
        let facing = Light::sun(&SunLight {
            direction: [0.0, 0.0, -1.0],
            ..sun.clone()
        });
        let e = facing.radiance.x * std::f64::consts::PI * ltc_diffuse(&facing);
        assert!(
            (e - 3.0).abs() / 3.0 < 2e-3,
            "diameter {diameter}, facing: {e}"
        );
    }
}

#[test]
fn the_monte_carlo_sees_the_sphere_too() {
    let c = DVec3::new(0.8, 0.3, 1.5);
    let r = 0.4;
    let light = Light::sphere(&point_light(c, r, 2.0));
    let brdf = Brdf::new(1.0, DVec3::splat(0.7), DVec3::ZERO);
    let sp = ShadingPoint {
        position: DVec3::ZERO,
        normal: DVec3::Z,
        geometric: DVec3::Z,
        wo: DVec3::Z,
    };
    let shadows = Shadows {
        occluder: None,
        epsilon: 1e-6,
        lamps: Vec::new(),
    };
    let mut rng = Pcg32::new(5, 0);
    let est = shade_mc(&sp, &brdf, &light, &shadows, 100_000, &mut rng);
    let d = c.length();
    let want = 0.7 / std::f64::consts::PI
        * light.radiance.x
        * std::f64::consts::PI
        * (r / d).powi(2)
        * (c.z / d);
    let se = est.std_error().x;
    assert!(
        (est.mean.x - want).abs() < 4.0 * se + 1e-3 * want,
        "MC {} ± {se} vs {want}",
        est.mean.x
    );
}

#[test]
fn a_spot_lights_its_cone_only() {
    let mut l = point_light(DVec3::new(0.0, 0.0, 2.0), 0.05, 1.0);
    l.spot = Some(Spot {
        direction: [0.0, 0.0, -1.0],
        inner_cone_angle: 0.2,
        outer_cone_angle: 0.3,
    });
    let light = Light::sphere(&l);
    // Under the spot: full; beside it, outside the cone: nothing.
    assert!(light.radiance_toward(DVec3::ZERO).x > 0.0);
    assert!(light.faces(DVec3::ZERO));
    let beside = DVec3::new(3.0, 0.0, 0.0);
    assert_eq!(light.radiance_toward(beside).x, 0.0);
    assert!(!light.faces(beside));
}

#[test]
fn no_nan_near_inside_or_far_from_a_sphere() {
    for (p, scale) in [
        (DVec3::new(0.0, 0.0, 0.0), 1.0),
        (DVec3::new(0.0, 0.0, 1.0), 1.0),         // at the centre
        (DVec3::new(0.0, 0.0, 0.5), 1.0),         // on the surface
        (DVec3::new(0.0, 0.0, 0.5 - 1e-12), 1.0), // a hair outside
        (DVec3::new(1e-7, 0.0, 0.0), 1e-6),
        (DVec3::new(3.0, 1.0, 0.0), 1e6),
    ] {
        let c = DVec3::new(0.0, 0.0, 1.0) * scale;
        let light = Light::sphere(&point_light(c, 0.5 * scale, 1.0));
        let p = p * scale;
        let s = unshadowed(&diffuse_lobes(DVec3::Z), &light, p, DVec3::Z);
        assert!(
            s.integrals.diffuse.is_finite() && s.integrals.specular.is_finite(),
            "{p}: {s:?}"
        );
        assert!(s.integrals.diffuse >= 0.0 && s.integrals.diffuse <= 1.0 + 1e-9);
        let sp = ShadingPoint {
            position: p,
            normal: DVec3::Z,
            geometric: DVec3::Z,
            wo: DVec3::Z,
        };
        let shadows = Shadows {
            occluder: None,
            epsilon: 1e-6 * scale,
            lamps: Vec::new(),
        };
        let brdf = Brdf::new(0.3, DVec3::splat(0.5), DVec3::splat(0.04));
        let est = shade_mc(&sp, &brdf, &light, &shadows, 64, &mut Pcg32::new(1, 0));
        assert!(est.mean.is_finite(), "{p}: {:?}", est.mean);
    }
}
