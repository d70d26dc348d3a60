// Submitting from the browser: which dropped file is the mesh, which the scene, under which
// names the others go (the multipart form of docs/service.md, "Submitting"), and the upload
// itself with its progress.

const MESH = /\.(glb|gltf|obj|ply)(\.zst)?$/i;
const SCENE = /\.json$/i;

/** Every file of a drop, folders walked, each with its path inside the drop (`a/b.png`). */
export async function droppedFiles(dataTransfer) {
  const entries = [...dataTransfer.items]
    .map((item) => (item.webkitGetAsEntry ? item.webkitGetAsEntry() : null))
    .filter(Boolean);
  if (entries.length === 0) {
    return [...dataTransfer.files].map((file) => ({ path: file.name, file }));
  }
  const out = [];
  const walk = async (entry, prefix) => {
    if (entry.isFile) {
      const file = await new Promise((ok, fail) => entry.file(ok, fail));
      out.push({ path: prefix + entry.name, file });
    } else if (entry.isDirectory) {
      const reader = entry.createReader();
      // readEntries answers in batches until an empty one.
      for (;;) {
        const batch = await new Promise((ok, fail) => reader.readEntries(ok, fail));
        if (batch.length === 0) break;
        for (const e of batch) await walk(e, `${prefix}${entry.name}/`);
      }
    }
  };
  for (const e of entries) await walk(e, '');
  return out;
}

/** The files of an `<input type=file>` (a folder's keep their relative paths). */
export function pickedFiles(input) {
  return [...input.files].map((file) => ({ path: file.webkitRelativePath || file.name, file }));
}

/**
 * The form fields for `files` ({path, file}): `{mesh, scene, others: [{name, file}], skipped}`,
 * or `{error}` saying what is wrong. The mesh's companions are named by their path relative to
 * the mesh's folder (`tex/wall.png`), as the mesh refers to them; files outside that folder go
 * by their own name (the scene's light textures); hidden files are left out.
 */
export function classify(files) {
  const visible = files.filter((f) => !f.path.split('/').some((c) => c.startsWith('.')));
  const meshes = visible.filter((f) => MESH.test(f.path));
  const scenes = visible.filter((f) => SCENE.test(f.path));
  if (meshes.length > 1) {
    return { error: `one mesh at a time: this drop has ${meshes.length} (${names(meshes)})` };
  }
  if (scenes.length > 1) {
    return { error: `one scene file at a time: this drop has ${scenes.length} (${names(scenes)})` };
  }
  const mesh = meshes[0];
  const scene = scenes[0];
  if (!mesh && !scene) {
    return { error: 'no mesh in this drop: a .glb, .gltf, .obj or .ply (or a scene .json)' };
  }
  const base = dirOf((mesh ?? scene).path);
  const others = [];
  const skipped = [];
  const taken = new Set();
  for (const f of visible) {
    if (f === mesh || f === scene) continue;
    const name = f.path.startsWith(base) ? f.path.slice(base.length) : f.path.split('/').pop();
    if (taken.has(name)) {
      skipped.push(f.path);
      continue;
    }
    taken.add(name);
    others.push({ name, file: f.file });
  }
  return { mesh, scene, others, skipped };
}

function dirOf(path) {
  const i = path.lastIndexOf('/');
  return i < 0 ? '' : path.slice(0, i + 1);
}

function names(fs) {
  return fs.map((f) => f.path).join(', ');
}

/**
 * POSTs the form to `url` with `headers`; `onProgress(sent, total)` while the body goes out.
 * Resolves to `{status, body}` (the JSON answer), rejects only when the request could not be
 * made. XMLHttpRequest because fetch reports no upload progress.
 */
export function submit(url, form, headers, onProgress) {
  const body = new FormData();
  if (form.mesh) body.append('mesh', form.mesh.file, form.mesh.path.split('/').pop());
  if (form.scene) body.append('scene', form.scene.file, form.scene.path.split('/').pop());
  for (const o of form.others) body.append('file', o.file, o.name);
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open('POST', url);
    for (const [k, v] of Object.entries(headers)) xhr.setRequestHeader(k, v);
    xhr.upload.onprogress = (e) => onProgress(e.loaded, e.lengthComputable ? e.total : 0);
    xhr.onload = () => {
      let parsed = null;
      try {
        parsed = JSON.parse(xhr.responseText);
      } catch {
        parsed = { error: 'bad_response', detail: xhr.responseText.slice(0, 300) };
      }
      resolve({ status: xhr.status, body: parsed });
    };
    xhr.onerror = () => reject(new Error('the request could not be sent (is the server up?)'));
    xhr.send(body);
  });
}
