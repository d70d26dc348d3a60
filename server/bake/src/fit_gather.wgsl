// The fit's read-back (gpu_fit.rs): the first `words` words of each face's output (its header
// and first nodes: a real face's tree is smaller) packed densely, one workgroup per face, so
// that a chunk reads back ~1 KiB a face instead of the whole output area (32 KiB at 64²).

struct Gather {
    faces: u32,
    out_words: u32,
    words: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> g: Gather;
@group(0) @binding(1) var<storage, read> result: array<u32>;
@group(0) @binding(2) var<storage, read_write> dense: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let f = wid.x;
    if f >= g.faces {
        return;
    }
    for (var w = lid; w < g.words; w += 64u) {
        dense[f * g.words + w] = result[f * g.out_words + w];
    }
}
