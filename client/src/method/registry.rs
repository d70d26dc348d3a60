//! The one list of rendering methods. `--method` values, `bspvt methods`, the viewer's method
//! keys (in this order), the report and the benchmarks all read it.

use super::FrameMethod;

/// Every method, in the viewer's key order (1, 2, …).
pub static METHODS: &[&dyn FrameMethod] = &[
    &super::bspvt::Bspvt,
    &super::ltc::Ltc,
    &super::mc::Mc,
    &super::rt_penumbra::RT_PENUMBRA,
    &super::pcss::PCSS,
    &super::pcf::PCF,
    &super::vsm::VSM,
    &super::sg::SgEnvironment,
    &super::mc_env::McEnv,
    &super::bspvt_env::BspvtEnv,
    &super::ltc_exact::LtcExact,
    &super::rt_hard::RT_HARD,
    &super::ratio::RATIO,
    &super::ratio::RATIO_DENOISED,
];

/// The method called `name`.
pub fn find(name: &str) -> Option<&'static dyn FrameMethod> {
    METHODS.iter().copied().find(|m| m.name() == name)
}

/// Every method's name, in registry order.
pub fn names() -> Vec<&'static str> {
    METHODS.iter().map(|m| m.name()).collect()
}

/// The method called `name`, or an error listing the known names.
pub fn lookup(name: &str) -> anyhow::Result<&'static dyn FrameMethod> {
    find(name).ok_or_else(|| {
        anyhow::anyhow!(
            "unknown method {name:?} (known: {}; `bspvt methods` describes them)",
            names().join(", ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_kebab_case_and_described() {
        let mut seen = std::collections::BTreeSet::new();
        for m in METHODS {
            assert!(seen.insert(m.name()), "{} listed twice", m.name());
            assert!(
                m.name()
                    .bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-'),
                "{} is not kebab-case",
                m.name()
            );
            assert!(!m.description().is_empty() && !m.description().contains('\n'));
            assert!(find(m.name()).is_some());
        }
        assert!(lookup("no-such-method").is_err());
    }
}
