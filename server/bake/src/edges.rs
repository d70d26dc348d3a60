//! Triangle edges matched by their two vertices, for the mesh walk's adjacency and the ray
//! origins' open boundaries: one sort of packed keys, not a hash map (a scanned mesh's three
//! million edges through SipHash were a tenth of a big bake's set-up).
//!
//! A math kernel: no I/O.

/// Every edge of `tris`, the edge of triangle t opposite its vertex k as the slot 3t + k,
/// keyed by its two vertex indices (in either order) and packed as key · 2⁶⁴ + slot, sorted:
/// the edges joining the same two vertices are runs, in slot order.
fn sorted(tris: &[[u32; 3]]) -> Vec<u128> {
    let mut edges: Vec<u128> = Vec::with_capacity(tris.len() * 3);
    for (t, idx) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (idx[(k + 1) % 3], idx[(k + 2) % 3]);
            let key = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
            edges.push((u128::from(key) << 64) | (3 * t + k) as u128);
        }
    }
    edges.sort_unstable();
    edges
}

/// The runs of [`sorted`]'s edges that join the same two vertices.
fn runs(edges: &[u128]) -> impl Iterator<Item = &[u128]> {
    edges.chunk_by(|a, b| a >> 64 == b >> 64)
}

/// (triangle, k) of an edge's slot.
fn slot(e: u128) -> (usize, usize) {
    let s = e as u64 as usize;
    (s / 3, s % 3)
}

/// Per triangle of `tris`, the triangle across the edge opposite each vertex, or `none`: of
/// the triangles sharing an edge, the first two (in order) are linked, so an edge of three or
/// more (non-manifold) links its first two.
pub(crate) fn across(tris: &[[u32; 3]], none: u32) -> Vec<[u32; 3]> {
    let mut across = vec![[none; 3]; tris.len()];
    for run in runs(&sorted(tris)) {
        if let [first, second, ..] = run {
            let ((p, k), (q, kq)) = (slot(*first), slot(*second));
            across[p][k] = q as u32;
            across[q][kq] = p as u32;
        }
    }
    across
}

/// Per vertex of a mesh of `vertex_count` vertices and triangles `tris`: whether it ends an
/// edge that only one triangle uses (an open boundary).
pub(crate) fn on_boundary(tris: &[[u32; 3]], vertex_count: usize) -> Vec<bool> {
    let mut on = vec![false; vertex_count];
    for run in runs(&sorted(tris)) {
        if let [only] = run {
            let key = (only >> 64) as u64;
            for v in [key >> 32, key & 0xffff_ffff] {
                if let Some(flag) = on.get_mut(v as usize) {
                    *flag = true;
                }
            }
        }
    }
    on
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use proptest::prelude::*;

    use super::*;

    /// The hash-map definitions the sort replaced (walk.rs and origin.rs before it).
    fn across_by_map(tris: &[[u32; 3]], none: u32) -> Vec<[u32; 3]> {
        let mut first: HashMap<(u32, u32), (u32, u8)> = HashMap::new();
        let mut across = vec![[none; 3]; tris.len()];
        for (p, idx) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (idx[(k + 1) % 3], idx[(k + 2) % 3]);
                let key = (a.min(b), a.max(b));
                match first.get(&key) {
                    Some(&(q, kq)) => {
                        if across[p][k] == none && across[q as usize][kq as usize] == none {
                            across[p][k] = q;
                            across[q as usize][kq as usize] = p as u32;
                        }
                    }
                    None => {
                        first.insert(key, (p as u32, k as u8));
                    }
                }
            }
        }
        across
    }

    fn on_boundary_by_map(tris: &[[u32; 3]], n: usize) -> Vec<bool> {
        let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut on = vec![false; n];
        for (&(a, b), &count) in &uses {
            if count == 1 {
                for v in [a, b] {
                    if let Some(flag) = on.get_mut(v as usize) {
                        *flag = true;
                    }
                }
            }
        }
        on
    }

    #[test]
    fn a_fan_and_a_fin() {
        // Two triangles sharing 0–1, a third on the same edge (a fin), one alone.
        let tris = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [5, 6, 7]];
        let across = across(&tris, u32::MAX);
        assert_eq!(across[0][2], 1, "0–1 is opposite vertex 2 of the first");
        assert_eq!(across[1][2], 0);
        assert_eq!(
            across[2],
            [u32::MAX; 3],
            "the fin's third triangle links nothing"
        );
        assert_eq!(across[3], [u32::MAX; 3]);
        let on = on_boundary(&tris, 9);
        assert_eq!(on, [true, true, true, true, true, true, true, true, false]);
    }

    proptest! {
        /// Small vertex ranges make shared, non-manifold and repeated-vertex edges common.
        #[test]
        fn the_sort_is_the_hash_maps(
            tris in prop::collection::vec(prop::array::uniform3(0u32..12), 0..60),
            extra in 0usize..4,
        ) {
            prop_assert_eq!(across(&tris, u32::MAX), across_by_map(&tris, u32::MAX));
            // Indices past the vertex count are ignored, as before.
            let n = 12usize.saturating_sub(extra * 3);
            prop_assert_eq!(on_boundary(&tris, n), on_boundary_by_map(&tris, n));
        }
    }
}
