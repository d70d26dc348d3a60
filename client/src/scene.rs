//! A scene as the bake sees it: loaded by `bspvt_proto`, then refined where its bake settings
//! ask (`bake.refine`, [`bspvt_bake::refine`]), so an offline render shades the very mesh that
//! the service and `bspvt-server bake` bake (refinement is deterministic).

use std::path::Path;

use anyhow::Result;
use bspvt_proto::Scene;

/// Opens a scene file, `builtin:NAME` or a bare mesh ([`bspvt_proto::scene::open_scene`]),
/// prints its loader's warnings and refines it when it asks.
pub fn open(scene: Option<&str>, mesh: Option<&Path>) -> Result<Scene> {
    let mut s = bspvt_proto::scene::open_scene(scene, mesh)?;
    for w in &s.warnings {
        tracing::warn!("{w}");
    }
    refine(&mut s)?;
    Ok(s)
}

/// Refines `scene` in place when its bake settings ask, saying what it did on stderr.
pub fn refine(scene: &mut Scene) -> Result<()> {
    if let Some(r) = bspvt_bake::refine::refine_scene(scene)? {
        eprintln!(
            "refined the mesh where shadows cross it: {} → {} vertices ({} splits{}) in {:.2} s",
            r.vertices_before,
            r.vertices_after,
            r.splits,
            if r.budget_reached {
                ", vertex budget reached"
            } else {
                ""
            },
            r.seconds
        );
    }
    Ok(())
}
