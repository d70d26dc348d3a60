//! What the report concludes from its measurements: the equal-time comparison of BSPVT with
//! the stochastic methods, and the split of BSPVT's error into its LTC-fit and visibility
//! parts. Pure functions of the measured numbers.

use serde::Serialize;

use super::scene::Entry;
use bspvt_client::render::renderer::Mode;

/// The target of the visibility part: ≤ 0.5 % of the unshadowed radiance (mean absolute).
pub(crate) const VISIBILITY_TARGET: f64 = 0.005;
/// The equal-time target: BSPVT's RMSE ≤ ¼ of the best stochastic method's.
pub(crate) const EQUAL_TIME_TARGET: f64 = 0.25;

/// The stochastic methods BSPVT is compared with at equal time.
pub(crate) const STOCHASTIC: [&str; 3] = ["mc", "ratio", "ratio-denoised"];

/// BSPVT's mean absolute error against the ground truth, split in two (per bake and mode):
///
/// ```text
/// |BSPVT − GT| ≤ |BSPVT − LTC·V_exact| + |LTC·V_exact − GT|
///                 visibility part        LTC-fit part
/// ```
///
/// where LTC·V_exact is LTC shading with visibility by many shadow rays (its own noise,
/// `reference_noise`, is in the visibility part's figure: subtract it to read a bound). In
/// per-vertex mode the visibility part also holds the interpolation across triangles.
#[derive(Clone, Debug, Serialize)]
pub struct Budget {
    pub(crate) face_res: u32,
    pub(crate) epsilon: f32,
    pub(crate) mode: Mode,
    pub(crate) total_mae: f64,
    pub(crate) visibility_mae: f64,
    pub(crate) ltc_fit_mae: f64,
    pub(crate) reference_noise_mae: f64,
    /// The parts over the mean unshadowed radiance.
    pub visibility_share: f64,
    pub ltc_fit_share: f64,
    /// `visibility_share` ≤ [`VISIBILITY_TARGET`].
    pub(crate) visibility_target_met: bool,
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn budget(
    face_res: u32,
    epsilon: f32,
    mode: Mode,
    unshadowed_mean: f64,
    visibility_mae: f64,
    ltc_fit_mae: f64,
    total_mae: f64,
    reference_noise_mae: f64,
) -> Budget {
    let share = |x: f64| {
        if unshadowed_mean > 0.0 {
            x / unshadowed_mean
        } else {
            f64::NAN
        }
    };
    let visibility_share = share(visibility_mae);
    Budget {
        face_res,
        epsilon,
        mode,
        total_mae,
        visibility_mae,
        ltc_fit_mae,
        reference_noise_mae,
        visibility_share,
        ltc_fit_share: share(ltc_fit_mae),
        visibility_target_met: visibility_share <= VISIBILITY_TARGET,
    }
}

/// How a stochastic method's RMSE at a given frame time was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum Reading {
    /// Log-log interpolation between the two sample counts whose times bracket it.
    Interpolated,
    /// The time is below the method's 1-sample frame time: the method cannot run that fast;
    /// its 1-sample RMSE is used (a bound in the stochastic method's favour).
    SlowerAtOneSample,
    /// The time is above the largest sample count's: extrapolated with RMSE ∝ t^(−½), the
    /// Monte Carlo rate.
    Extrapolated,
}

/// BSPVT at one setting against the best stochastic method at the same frame time.
#[derive(Clone, Debug, Serialize)]
pub struct EqualTime {
    pub(crate) bspvt: String,
    pub(crate) ms_per_frame: f64,
    pub(crate) rmse: f64,
    /// The stochastic method with the lowest RMSE at that time, its RMSE and how it was read.
    pub(crate) best: String,
    pub(crate) best_rmse: f64,
    pub(crate) reading: Reading,
    /// `rmse / best_rmse`; the target is ≤ [`EQUAL_TIME_TARGET`].
    pub(crate) ratio: f64,
    pub(crate) target_met: bool,
}

/// The equal-time comparison for every BSPVT entry of one scene.
pub(crate) fn equal_time(entries: &[Entry]) -> Vec<EqualTime> {
    entries
        .iter()
        .filter(|e| e.method == "bspvt")
        .filter_map(|b| {
            let (best, (best_rmse, reading)) = STOCHASTIC
                .iter()
                .filter_map(|m| {
                    let curve: Vec<(f64, f64)> = entries
                        .iter()
                        .filter(|e| e.method == *m)
                        .map(|e| (e.ms_per_frame, e.metrics.rmse))
                        .collect();
                    rmse_at_time(&curve, b.ms_per_frame).map(|r| (m.to_string(), r))
                })
                .min_by(|a, b| a.1.0.total_cmp(&b.1.0))?;
            let ratio = b.metrics.rmse / best_rmse.max(f64::MIN_POSITIVE);
            Some(EqualTime {
                bspvt: b.label(),
                ms_per_frame: b.ms_per_frame,
                rmse: b.metrics.rmse,
                best,
                best_rmse,
                reading,
                ratio,
                target_met: ratio <= EQUAL_TIME_TARGET,
            })
        })
        .collect()
}

/// A stochastic method's RMSE at frame time `t` from its (time, RMSE) points (any order).
/// Times are made non-decreasing in sample order first: a noisy timing of a cheap point must
/// not fold the curve back.
pub(crate) fn rmse_at_time(curve: &[(f64, f64)], t: f64) -> Option<(f64, Reading)> {
    let mut pts: Vec<(f64, f64)> = curve
        .iter()
        .copied()
        .filter(|(t, e)| t.is_finite() && *t > 0.0 && e.is_finite() && *e > 0.0)
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (first, last) = (*pts.first()?, *pts.last()?);
    if t <= first.0 {
        return Some((first.1, Reading::SlowerAtOneSample));
    }
    if t >= last.0 {
        return Some((last.1 * (t / last.0).powf(-0.5), Reading::Extrapolated));
    }
    let w = pts.windows(2).find(|w| w[0].0 <= t && t <= w[1].0)?;
    let (a, b) = (w[0], w[1]);
    let f = if b.0 > a.0 {
        (t.ln() - a.0.ln()) / (b.0.ln() - a.0.ln())
    } else {
        0.0
    };
    Some((
        (a.1.ln() + f * (b.1.ln() - a.1.ln())).exp(),
        Reading::Interpolated,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_curve_inside_below_and_above() {
        // RMSE ∝ t^(−½): 1 ms → 0.1, 4 ms → 0.05, 16 ms → 0.025.
        let curve = [(4.0, 0.05), (1.0, 0.1), (16.0, 0.025)];
        let (e, r) = rmse_at_time(&curve, 2.0).expect("point");
        assert_eq!(r, Reading::Interpolated);
        assert!((e - 0.1 / 2f64.sqrt()).abs() < 1e-12, "{e}");
        assert_eq!(
            rmse_at_time(&curve, 0.5),
            Some((0.1, Reading::SlowerAtOneSample))
        );
        let (e, r) = rmse_at_time(&curve, 64.0).expect("point");
        assert_eq!(r, Reading::Extrapolated);
        assert!((e - 0.0125).abs() < 1e-12);
        assert_eq!(rmse_at_time(&[], 1.0), None);
        assert_eq!(rmse_at_time(&[(f64::NAN, 0.1)], 1.0), None);
    }

    #[test]
    fn budget_shares_and_target() {
        let b = budget(64, 1e-3, Mode::Pixel, 0.5, 0.002, 0.01, 0.011, 0.0005);
        assert!((b.visibility_share - 0.004).abs() < 1e-12);
        assert!((b.ltc_fit_share - 0.02).abs() < 1e-12);
        assert!(b.visibility_target_met);
        let b = budget(64, 1e-3, Mode::Pixel, 0.5, 0.003, 0.01, 0.011, 0.0005);
        assert!(!b.visibility_target_met);
        assert!(!budget(64, 1e-3, Mode::Pixel, 0.0, 0.0, 0.0, 0.0, 0.0).visibility_target_met);
    }
}
