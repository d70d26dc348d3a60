//! The headless renderer: camera, primary visibility, per-frame shading, image output.

pub mod path;
pub mod posed;
pub mod renderer;
pub mod sky_cells;
