//! The trainer page (`GET /` and its assets): raw WebGL2 and ES modules, embedded in the
//! binary, nothing fetched from elsewhere at run time. The page connects to `/session`
//! (`docs/live.md`); `main.js` documents the state it exposes on `window.peLive` for tests.

/// `(file, content type, bytes)` of every file the page loads.
const ASSETS: &[(&str, &str, &[u8])] = &[
    ("index.html", HTML, include_bytes!("index.html")),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_bytes!("style.css"),
    ),
    ("main.js", JS, include_bytes!("main.js")),
    ("session.js", JS, include_bytes!("session.js")),
    ("instrument.js", JS, include_bytes!("instrument.js")),
    ("camera.js", JS, include_bytes!("camera.js")),
    ("render.js", JS, include_bytes!("render.js")),
    ("hud.js", JS, include_bytes!("hud.js")),
    ("math.js", JS, include_bytes!("math.js")),
];
const HTML: &str = "text/html; charset=utf-8";
const JS: &str = "text/javascript; charset=utf-8";

/// The content type and bytes of the page's file at the request path `path` (`/` is
/// `index.html`; a query or fragment is ignored), or `None` when the page has no such file.
pub fn asset(path: &str) -> Option<(&'static str, &'static [u8])> {
    let path = path.split(['?', '#']).next().unwrap_or("");
    let name = path.trim_start_matches('/');
    let name = if name.is_empty() { "index.html" } else { name };
    ASSETS
        .iter()
        .find(|(file, ..)| *file == name)
        .map(|&(_, kind, bytes)| (kind, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// The text after each `marker` up to `close`.
    fn quoted<'a>(text: &'a str, marker: &str, close: char) -> Vec<&'a str> {
        text.match_indices(marker)
            .filter_map(|(i, _)| text[i + marker.len()..].split(close).next())
            .collect()
    }

    /// Every `./x.js` a module imports and every `src`/`href` of the page that is not a
    /// data: URL, read from the embedded files themselves.
    fn references() -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        for (file, _, bytes) in ASSETS {
            let text = std::str::from_utf8(bytes).expect("the page's files are UTF-8");
            let mut refs = quoted(text, "from './", '\'');
            if file.ends_with(".html") {
                refs.extend(quoted(text, "src=\"", '"'));
                refs.extend(quoted(text, "href=\"", '"'));
            }
            out.extend(
                refs.into_iter()
                    .filter(|r| !r.starts_with("data:"))
                    .map(String::from),
            );
        }
        out
    }

    #[test]
    fn every_file_the_page_loads_is_served_and_every_served_file_is_in_the_folder() {
        let refs = references();
        // The page loads its stylesheet, its entry module and the modules it imports.
        assert!(refs.len() >= 8, "too few references found: {refs:?}");
        for r in &refs {
            let name = r.trim_start_matches("./");
            assert!(
                asset(&format!("/{name}")).is_some(),
                "the page loads {r}, which is not served"
            );
        }
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/live/web");
        let on_disk: BTreeSet<String> = std::fs::read_dir(&dir)
            .expect("the page's folder")
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| !n.ends_with(".rs"))
            .collect();
        let served: BTreeSet<String> = ASSETS.iter().map(|(f, ..)| f.to_string()).collect();
        assert_eq!(
            on_disk, served,
            "the folder's files and the served ones differ"
        );
    }

    #[test]
    fn paths_map_to_files_with_their_types() {
        let (kind, bytes) = asset("/").expect("the page");
        assert_eq!(kind, HTML);
        assert!(std::str::from_utf8(bytes)
            .unwrap()
            .contains("<canvas id=\"view\""));
        assert_eq!(asset("/index.html?x=1").map(|a| a.0), Some(HTML));
        assert_eq!(asset("/main.js").map(|a| a.0), Some(JS));
        assert_eq!(
            asset("/style.css").map(|a| a.0),
            Some("text/css; charset=utf-8")
        );
        assert!(asset("/nope.js").is_none());
        assert!(asset("/../Cargo.toml").is_none());
        assert!(asset("/session").is_none());
    }
}
