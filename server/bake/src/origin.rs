//! Where a vertex's rays start.
//!
//! A vertex's rays leave from its position lifted off its own surface along the normal. That
//! is not enough where another surface passes through the vertex: in a room built of separate
//! parts (the Cornell box's floor, walls and ceiling are five quads whose corners and edges
//! coincide), a wall's top-edge vertex lies *on* the ceiling's plane, and lifting it along the
//! wall's normal keeps it there: every ray toward the ceiling crosses it at t ≈ 0, below the
//! bake's `t_min`, and escapes — to the sky, above the room. Half the hemisphere leaks at every
//! junction vertex, and per-vertex interpolation spreads the leak over the triangles around it
//! (the sky in the Cornell box came out 40–50 % too bright).
//!
//! A vertex on an open boundary of its part (an edge used by one triangle) is therefore also
//! moved into its own part, along the surface: toward the triangles around it, by the same
//! offset. A surface meeting that boundary is then crossed at t ≥ offset × |cos| (well above
//! `t_min` but for rays almost parallel to it, which cross it far away and are blocked). Inside
//! a surface (every edge shared) nothing changes: a closed mesh bakes to the same bytes.
//!
//! A math kernel: no I/O.

use bspvt_proto::Mesh;
use glam::Vec3;

/// The ray origin of every vertex of `mesh`: position + `offset` × (normal + the unit
/// direction into its own triangles, for a vertex on an open boundary).
pub(crate) fn ray_origins(mesh: &Mesh, offset: f32) -> Vec<Vec3> {
    let inward = boundary_inward(mesh);
    mesh.positions
        .iter()
        .zip(&mesh.normals)
        .zip(&inward)
        .map(|((&p, &n), &t)| p + (n + t) * offset)
        .collect()
}

/// Per vertex: zero inside a surface; on an open boundary, the unit tangential direction from
/// the vertex toward the centroids of the triangles around it (the side its surface lies on).
pub(crate) fn boundary_inward(mesh: &Mesh) -> Vec<Vec3> {
    let n = mesh.positions.len();
    let on_boundary = crate::edges::on_boundary(&mesh.triangles, n);
    // Σ over the triangles around a boundary vertex of (centroid − vertex), in f64 so that the
    // sum's order (triangle order) cannot change a bit of the result's direction materially.
    let mut toward = vec![glam::DVec3::ZERO; n];
    for t in &mesh.triangles {
        let [Some(a), Some(b), Some(c)] = t.map(|v| mesh.positions.get(v as usize)) else {
            continue;
        };
        let corners = [a, b, c].map(|p| p.as_dvec3());
        let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
        for (&v, &p) in t.iter().zip(&corners) {
            if on_boundary[v as usize] {
                toward[v as usize] += centroid - p;
            }
        }
    }
    toward
        .iter()
        .zip(&mesh.normals)
        .map(|(&s, &nrm)| tangential_unit(s, nrm))
        .collect()
}

/// The unit component of `toward` perpendicular to `normal` (zero when there is none).
pub(crate) fn tangential_unit(toward: glam::DVec3, normal: Vec3) -> Vec3 {
    let nrm = normal.as_dvec3();
    let tangential = toward - nrm * toward.dot(nrm);
    let len = tangential.length();
    if len > 0.0 && len.is_finite() {
        (tangential / len).as_vec3()
    } else {
        Vec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(corners: [Vec3; 4], normal: Vec3) -> Mesh {
        Mesh {
            positions: corners.to_vec(),
            normals: vec![normal; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            material_ids: vec![0, 0],
            ..Mesh::default()
        }
    }

    /// A floor quad's corners move diagonally into the quad; a vertex inside a closed surface
    /// does not move along it.
    #[test]
    fn boundary_vertices_move_into_their_surface() {
        let floor = quad(
            [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(1.0, 0.0, 0.0),
            ],
            Vec3::Y,
        );
        let o = ray_origins(&floor, 0.01);
        let s = std::f32::consts::FRAC_1_SQRT_2 * 0.01;
        let want = Vec3::new(s, 0.01, s);
        assert!((o[0] - want).length() < 1e-6, "{:?}", o[0]);
        let want = Vec3::new(1.0 - s, 0.01, 1.0 - s);
        assert!((o[2] - want).length() < 1e-6, "{:?}", o[2]);

        // A tetrahedron: every edge shared, origins = position + offset × normal.
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let tet = Mesh {
            positions: p.to_vec(),
            normals: p
                .iter()
                .map(|&q| (q - Vec3::splat(0.25)).normalize())
                .collect(),
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            material_ids: vec![0; 4],
            ..Mesh::default()
        };
        let o = ray_origins(&tet, 0.01);
        for v in 0..4 {
            assert_eq!(o[v], p[v] + tet.normals[v] * 0.01);
        }
    }
}
