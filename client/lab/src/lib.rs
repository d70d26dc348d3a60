//! # bspvt-lab
//!
//! bspvt's research tooling, built on the client library: the error-against-run-time
//! [`report`] of every method against converged Monte Carlo, image comparison ([`compare`]),
//! the shading and method benchmarks ([`bench`], [`method_bench`], [`penumbra_bench`], [`sg_bench`], [`sky_bench`],
//! [`refine_bench`]), the
//! project's LTC fit of GGX ([`ltc_fit`]) and the Mitsuba 3 export ([`mitsuba`]).
//!
//! Depends on `bspvt-client` and the bake engine; nothing but the command line depends on it.
//! Its argument structs derive clap's `Args` (the command line flattens them).

#![warn(unreachable_pub, missing_docs)]

pub mod bench;
pub mod compare;
pub mod gpu_bench;
pub mod ltc_fit;
pub mod method_bench;
pub mod mitsuba;
pub mod penumbra_bench;
pub mod refine_bench;
pub mod report;
pub mod sg_bench;
pub mod sky_bench;
