//! The browser pages: the dashboard (`GET /`), the viewer (`GET /view/{id}`: WebGPU, streaming
//! the trees) and their files under `/ui/`, embedded in the binary (plain ES modules and CSS in
//! `server/web/`, no build step, nothing fetched from elsewhere); the viewer's shaders under
//! `/ui/wgsl/` are `bspvt_shaders::gpu::wgsl`'s, the sources the native client compiles.
//!
//! The page holds no data: it reads and writes through the public API with the same rules
//! (reads need no key; writes and the listing need the key when the server has one, which the
//! page keeps in `sessionStorage` and sends as `Authorization: Bearer`). Every URL the page
//! uses is relative to its own module (`new URL("../", import.meta.url)`), so it works behind
//! a reverse proxy that serves the service under a path prefix (`/bspvt/` → `/`).
//!
//! Every response carries a strict Content-Security-Policy: scripts and styles only from this
//! origin's files (no inline script or style), connections only to this origin, no framing.

use axum::extract::Path;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, get};

use super::error::ApiError;
use super::http::{not_modified, not_modified_response};
use super::state::Shared;

/// The policy of every page and file: nothing inline, nothing from another origin.
pub(crate) const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; \
     img-src 'self' data: blob:; connect-src 'self'; base-uri 'none'; form-action 'none'; \
     frame-ancestors 'none'";

/// An embedded file: its name under `/ui/`, media type and bytes.
struct Asset {
    name: &'static str,
    media_type: &'static str,
    bytes: &'static [u8],
}

const INDEX: Asset = Asset {
    name: "index.html",
    media_type: "text/html; charset=utf-8",
    bytes: include_bytes!("../../web/index.html"),
};

/// The viewer's page (`/view/{id}`; the id is read by the page from its own URL).
const VIEW: Asset = Asset {
    name: "view.html",
    media_type: "text/html; charset=utf-8",
    bytes: include_bytes!("../../web/view.html"),
};

/// The files `/ui/{name}` serves.
const ASSETS: &[Asset] = &[
    Asset {
        name: "dashboard.js",
        media_type: "text/javascript; charset=utf-8",
        bytes: include_bytes!("../../web/dashboard.js"),
    },
    Asset {
        name: "viewer.js",
        media_type: "text/javascript; charset=utf-8",
        bytes: include_bytes!("../../web/viewer.js"),
    },
    Asset {
        name: "cpu.js",
        media_type: "text/javascript; charset=utf-8",
        bytes: include_bytes!("../../web/cpu.js"),
    },
    Asset {
        name: "upload.js",
        media_type: "text/javascript; charset=utf-8",
        bytes: include_bytes!("../../web/upload.js"),
    },
    Asset {
        name: "icon.svg",
        media_type: "image/svg+xml",
        bytes: include_bytes!("../../web/icon.svg"),
    },
    Asset {
        name: "style.css",
        media_type: "text/css; charset=utf-8",
        bytes: include_bytes!("../../web/style.css"),
    },
];

/// The dashboard's routes (not part of the API document).
pub(crate) fn routes() -> Vec<(&'static str, MethodRouter<Shared>)> {
    vec![
        ("/", get(index)),
        ("/view/{id}", get(view)),
        ("/ui/{name}", get(asset)),
        ("/ui/wgsl/{name}", get(shader)),
    ]
}

async fn index(headers: HeaderMap) -> Response {
    serve(&INDEX, &headers)
}

/// The viewer's page for any id: the page asks the API for the scene and says what it got
/// (an unknown id is the API's 404, shown on the page).
async fn view(Path(_id): Path<String>, headers: HeaderMap) -> Response {
    serve(&VIEW, &headers)
}

/// The GPU path's shaders as the native client compiles them (`bspvt_shaders::gpu::wgsl`):
/// one source of truth for wgpu and the browser's WebGPU. Frames of one sample per pixel.
async fn shader(Path(name): Path<String>, headers: HeaderMap) -> Response {
    use bspvt_shaders::gpu::wgsl;
    let source: String = match name.as_str() {
        "shade.wgsl" => wgsl::shade(),
        "visibility.wgsl" => wgsl::visibility(),
        "resolve.wgsl" => wgsl::resolve(1),
        "present.wgsl" => wgsl::present().to_string(),
        "sides.wgsl" => wgsl::sides(),
        _ => {
            return ApiError::new(StatusCode::NOT_FOUND, "not_found", "no such shader")
                .into_response();
        }
    };
    serve_bytes("text/wgsl; charset=utf-8", source.as_bytes(), &headers)
}

async fn asset(Path(name): Path<String>, headers: HeaderMap) -> Response {
    match ASSETS.iter().find(|a| a.name == name) {
        Some(a) => serve(a, &headers),
        None => ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            "no such file of the dashboard",
        )
        .into_response(),
    }
}

/// The file with its validators and the security headers; 304 when the browser has it.
fn serve(a: &Asset, req: &HeaderMap) -> Response {
    serve_bytes(a.media_type, a.bytes, req)
}

fn serve_bytes(media_type: &'static str, bytes: &[u8], req: &HeaderMap) -> Response {
    // The bytes are fixed for the binary: their CRC-32 is a strong validator.
    let etag = format!("\"{:08x}-{}\"", crc32fast::hash(bytes), bytes.len());
    let mut r = if not_modified(req, &etag) {
        not_modified_response(&etag)
    } else {
        let mut r = bytes.to_vec().into_response();
        r.headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static(media_type));
        if let Ok(v) = HeaderValue::from_str(&etag) {
            r.headers_mut().insert(header::ETAG, v);
        }
        r
    };
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    // Revalidate every load: a new server version serves new files at the same names.
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No inline script or style in the pages, and every reference in them relative (a path
    /// prefix keeps working): what the policy and the prefix promise rest on.
    #[test]
    fn the_pages_have_no_inline_code_and_only_relative_references() {
        for (page, dir) in [(&INDEX, "ui/"), (&VIEW, "../ui/")] {
            let html = std::str::from_utf8(page.bytes).expect("UTF-8");
            for bad in [
                " style=",
                "<style",
                "javascript:",
                " onclick",
                " onload",
                "=\"/",
            ] {
                assert!(!html.contains(bad), "{} contains {bad:?}", page.name);
            }
            for part in html.split("<script").skip(1) {
                let tag = part.split('>').next().unwrap_or("");
                assert!(
                    tag.contains(&format!(" src=\"{dir}")),
                    "{}: a script not from {dir}: <script{tag}>",
                    page.name
                );
            }
        }
        for a in ASSETS.iter().filter(|a| a.name.ends_with(".js")) {
            let js = std::str::from_utf8(a.bytes).expect("UTF-8");
            // API paths are joined to the module's URL, never written from the root.
            for bad in ["\"/v1", "'/v1", "`/v1", "innerHTML", "eval("] {
                assert!(!js.contains(bad), "{} contains {bad:?}", a.name);
            }
        }
    }
}
