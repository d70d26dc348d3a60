//! `bspvt methods`: every registered method, one a line — its name, what it needs, and its
//! one-line description.

use bspvt_client::method::METHODS;

/// Prints the registry.
pub(crate) fn run() {
    let width = METHODS.iter().map(|m| m.name().len()).max().unwrap_or(0);
    for m in METHODS {
        println!(
            "{:width$}  {} (needs: {})",
            m.name(),
            m.description(),
            m.needs().describe()
        );
    }
}
