//! The layering of `src/` (docs/ARCHITECTURE.md): each top-level module imports only modules
//! below it in [`LAYERS`], so there is no import circle and no upward import. Read from the source
//! text: every `crate::name` path outside comments, `use crate::{a, b}` groups included.

use crate::common::root;
use std::collections::BTreeMap;
use std::path::Path;

/// The top-level modules of the library, bottom first: a module may import only those before it.
const LAYERS: &[&str] = &[
    "error",
    "files",
    "cpu",
    "geometry",
    "rng",
    "linalg",
    "crew",
    "registry",
    "params",
    "keys",
    "status",
    "imaging",
    "ssm",
    "dataset",
    "patches",
    "landscape",
    "observe",
    "am",
    "spec",
    "visual_tracker",
    "registration",
    "sm",
    "plan",
    "whole",
    "tracker",
    "catalogue",
    "gt",
    "eval",
    "bench",
    "report",
    "converge",
    "session",
    "app",
    "python",
];

/// The crate root's re-exports (`crate::Error` is `crate::error::Error`).
const ROOT_NAMES: &[(&str, &str)] = &[
    ("Error", "error"),
    ("Result", "error"),
    ("Point", "geometry"),
    ("Quad", "geometry"),
    ("Tracker", "tracker"),
    ("TrackerSpec", "tracker"),
];

/// The first path segments after each `crate::` in `code` (groups expanded at their top level).
fn crate_paths(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let (mut depth, mut item, mut end) = (0usize, String::new(), group.len());
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        end = k;
                        break;
                    }
                    '}' => depth -= 1,
                    _ => {}
                }
                if depth == 0 && c == ',' {
                    out.push(std::mem::take(&mut item));
                } else if depth == 0 {
                    item.push(c);
                }
            }
            out.push(item);
            rest = &group[end..];
        } else {
            out.push(
                rest.chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect(),
            );
        }
    }
    out.into_iter()
        .map(|p| {
            p.trim()
                .split("::")
                .next()
                .unwrap_or("")
                .trim()
                .trim_end_matches(['{', ' '])
                .to_string()
        })
        .filter(|p| !p.is_empty() && p != "self")
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).expect("src") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Per top-level module, the modules it imports, with a file that does.
fn imports() -> BTreeMap<String, BTreeMap<String, String>> {
    let src = root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut out: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for f in files {
        let rel = f
            .strip_prefix(&src)
            .expect("under src")
            .to_string_lossy()
            .to_string();
        if rel.starts_with("bin/") || rel == "lib.rs" {
            continue;
        }
        let top = rel
            .split('/')
            .next()
            .unwrap_or("")
            .trim_end_matches(".rs")
            .to_string();
        let text = std::fs::read_to_string(&f).expect("source");
        let code: String = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .map(|l| format!("{l}\n"))
            .collect();
        for p in crate_paths(&code) {
            let module = ROOT_NAMES
                .iter()
                .find(|(n, _)| *n == p)
                .map_or(p.clone(), |(_, m)| m.to_string());
            if module != top {
                out.entry(top.clone())
                    .or_default()
                    .insert(module, rel.clone());
            }
        }
    }
    out
}

#[test]
fn modules_import_only_the_layers_below_them() {
    let layer = |m: &str| LAYERS.iter().position(|l| *l == m);
    let mut wrong = Vec::new();
    let imports = imports();
    for (module, used) in &imports {
        let Some(own) = layer(module) else {
            wrong.push(format!(
                "module `{module}` is not in LAYERS (add it where it belongs)"
            ));
            continue;
        };
        for (dep, file) in used {
            match layer(dep) {
                Some(d) if d < own => {}
                Some(_) => wrong.push(format!("{module} imports {dep} (above it), in src/{file}")),
                None => wrong.push(format!(
                    "src/{file} uses crate::{dep}, not a module of LAYERS"
                )),
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The test reads what it should: the factory imports the registration driver.
    assert!(
        imports["tracker"].contains_key("registration"),
        "{imports:?}"
    );
}

#[test]
fn crate_paths_are_read_from_groups_too() {
    assert_eq!(
        crate_paths("use crate::{am, sm::{self, X}, Error};\nlet x = crate::ssm::build(a);"),
        ["am", "sm", "Error", "ssm"]
    );
}

/// The inspector's modules (`src/app/*.rs`, `panels/` as one) import one another without a
/// circle: the edges are the `super::name` and `crate::app::name` paths of each file (outside
/// comments) naming another of them.
#[test]
fn the_inspectors_modules_import_no_circle() {
    let app = root().join("src/app");
    let mut modules: Vec<String> = std::fs::read_dir(&app)
        .expect("src/app")
        .filter_map(|e| {
            let p = e.expect("entry").path();
            let name = p.file_stem()?.to_string_lossy().to_string();
            (p.is_dir() || p.extension().is_some_and(|x| x == "rs")).then_some(name)
        })
        .filter(|n| n != "mod")
        .collect();
    modules.sort();
    let mut edges: BTreeMap<String, std::collections::BTreeSet<String>> = BTreeMap::new();
    for m in &modules {
        let mut files = Vec::new();
        let dir = app.join(m);
        if dir.is_dir() {
            rust_files(&dir, &mut files);
        } else {
            files.push(app.join(format!("{m}.rs")));
        }
        for f in files {
            let text = std::fs::read_to_string(&f).expect("source");
            let code: String = text
                .lines()
                .filter(|l| !l.trim_start().starts_with("//"))
                .collect::<Vec<_>>()
                .join("\n");
            for prefix in ["super::", "crate::app::"] {
                for (i, _) in code.match_indices(prefix) {
                    let name: String = code[i + prefix.len()..]
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    // Inside panels/, `super::` is panels itself.
                    let own = dir.is_dir() && prefix == "super::";
                    if !own && &name != m && modules.contains(&name) {
                        edges.entry(m.clone()).or_default().insert(name);
                    }
                }
            }
        }
    }
    // The test reads what it should: the worker uses the decoder.
    assert!(edges["worker"].contains("decoder"), "{edges:?}");
    // Depth-first: a module met again on the current path closes a circle.
    fn visit(
        m: &str,
        edges: &BTreeMap<String, std::collections::BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut std::collections::BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(k) = path.iter().position(|p| p == m) {
            let mut circle = path[k..].to_vec();
            circle.push(m.to_string());
            return Some(circle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_string());
        for n in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(n, edges, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = std::collections::BTreeSet::new();
    for m in &modules {
        if let Some(c) = visit(m, &edges, &mut Vec::new(), &mut done) {
            panic!("an import circle in src/app: {}", c.join(" -> "));
        }
    }
}
