// The sky in world-fixed cells per vertex (client/src/shade/sky_cells.rs, issue 37 item 3):
//
//   L_o = albedo ⊙ Σ_c D_c L_c + spec ⊙ Σ_c ρ_c S_c L_c
//   D_c = Σᵢ v̄ᵢ ∫_{Ωᵢ} cos θ/π over the pieces the vertex's sky trees cut from cell c
//   ρ_c = D_c / ∫_{c ∩ H(n)} cos θ/π,   S_c = ∫_{c ∩ H(n)} D_ltc
//
// `sky_terms` makes (D_c, ρ_c S_c) of every visible vertex and cell (when the camera, the
// materials or the trees change); `sky_gather` is a frame of a turning map: the two sums with
// this frame's cell radiances L_c. `sky_terms`: one invocation per visible vertex and group of
// cells (the dispatch's y: llvmpipe ends an invocation after 65,535 loop iterations in all, which
// one vertex's 288 cells through its trees exceed); `sky_gather`: one per vertex. Prepended: common.wgsl,
// shade.wgsl (the surface, the tree walk); the light record is unused (untextured: the
// params' radiance.w is 0) and the light count is the number of cells.

// Each cell's corners (unit world directions), four vec4 per cell; the first's w is the
// corner count (3 at a pole, else 4).
@group(0) @binding(9) var<storage, read> cells: array<vec4f>;
// Per visible vertex (job) and cell: (D_c, ρ_c S_c).
@group(0) @binding(10) var<storage, read_write> terms: array<vec2f>;
// Per cell: its radiance this frame (SkyCells::radiance).
@group(0) @binding(11) var<storage, read> sky: array<vec4f>;

fn cell_count() -> u32 {
    return params.counts.x;
}

@compute @workgroup_size(64)
fn sky_terms(@builtin(global_invocation_id) gid: vec3u,
    @builtin(num_workgroups) groups: vec3u) {
    if gid.x >= params.counts.y {
        return;
    }
    // This invocation's cells: group gid.y of the dispatch's y groups.
    let per = (cell_count() + groups.y - 1u) / groups.y;
    let first = gid.y * per;
    let last = min(first + per, cell_count());
    let v = jobs[gid.x];
    let s = surface(v);
    flags = 0u;
    let em = emitter(s.p, s.frame, s.lt);
    // Trees not streamed in yet, or seen from behind: unshadowed
    // (render::renderer::Renderer::vertex_trees).
    let shadowed = roots[6u * v] != NO_TREES && !s.behind;
    let base = gid.x * cell_count();
    for (var c = first; c < last; c++) {
        let k = min(u32(cells[4u * c].w), 4u);
        for (var i = 0u; i < k; i++) {
            ig_src[i] = cells[4u * c + i].xyz;
        }
        // sphere::clip_into: the cell above the horizon of n.
        let nd = clip_src(s.n, k);
        var t = vec2f(0.0);
        if nd >= 3u {
            for (var i = 0u; i < nd; i++) {
                dirs[i] = ig_src[i];
            }
            let whole = shade_piece(nd, em);
            if whole.d.w > 0.0 {
                var d = whole.d.w;
                if shadowed {
                    d = walk(v, nd, em, false).sd.x;
                }
                if d > 0.0 {
                    t = vec2f(d, min(d / whole.d.w, 1.0) * whole.s.w);
                }
                // Out of walk room: the cell is flagged, never silently wrong.
                if (flags & OVERFLOW) != 0u {
                    t = vec2f(-1.0, 0.0);
                    flags = 0u;
                }
            }
        }
        terms[base + c] = t;
    }
}

@compute @workgroup_size(64)
fn sky_gather(@builtin(global_invocation_id) gid: vec3u) {
    if gid.x >= params.counts.y {
        return;
    }
    let v = jobs[gid.x];
    let s = surface(v);
    let base = gid.x * cell_count();
    var d = vec3f(0.0);
    var sp = vec3f(0.0);
    var f = 0u;
    for (var c = 0u; c < cell_count(); c++) {
        let t = terms[base + c];
        if t.x < 0.0 {
            f = OVERFLOW;
            continue;
        }
        let l = sky[c].xyz;
        d += t.x * l;
        sp += t.y * l;
    }
    var res: VertexOut;
    var colour = s.albedo * d + s.spec * sp;
    if !finite3(colour) {
        colour = vec3f(0.0);
        f = OVERFLOW;
    }
    res.colour = vec4f(colour, f32(f));
    res.ratio_d = vec3f(1.0);
    res.ratio_s = vec3f(1.0);
    res.pieces = 0u;
    res.dropped = 0u;
    results[v] = res;
}
