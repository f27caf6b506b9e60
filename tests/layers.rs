//! The crate's layers point one way (CONTRIBUTING.md, "Layers"), and its modules import
//! one another without a circle: every `crate::` and `super::` path of every source
//! file's non-test part is resolved to the module it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layer of a module, by the longest prefix of its path listed here: 0 is the
/// lowest. A module may import its own layer's modules and those below.
const LAYERS: &[(&str, usize)] = &[
    ("vector", 0),
    ("x86", 0),
    ("timing", 0),
    ("gpu_layout", 0),
    ("memo", 0),
    ("sh", 1),
    ("logsh", 1),
    ("heightfield", 1),
    ("scene", 1),
    ("synth", 1),
    // The per-point kernel.
    ("shade::point", 2),
    ("shade::exponentiator", 2),
    ("shade::settings", 2),
    ("shade::fitted_depth", 2),
    ("shade::blocker_tree", 2),
    ("shade::cap_packet", 2),
    ("shade::cap_detail", 2),
    ("shade::sun", 2),
    ("shade::sun_shadow", 2),
    ("shade::glossy", 2),
    ("shade::frame", 2),
    ("shade::kernel", 2),
    ("shade::sharp_lights", 2),
    // The frame plan and what is done to a frame's pixels as a whole.
    ("shade", 3),
    // The executors and their peers.
    ("shade::cpu", 4),
    ("gpu", 4),
    ("executor", 4),
    ("transfer", 4),
    ("reference", 4),
    // The application.
    ("compare", 5),
    ("plot", 5),
    ("sweep", 5),
    ("bench", 5),
    ("info", 5),
    ("render", 5),
    ("view", 5),
    ("cli", 5),
    ("run", 5),
    ("", 5),
];

fn layer(module: &[String]) -> usize {
    let path = module.join("::");
    LAYERS
        .iter()
        .filter(|(prefix, _)| prefix.is_empty() || path == *prefix || path.starts_with(&format!("{prefix}::")))
        .max_by_key(|(prefix, _)| prefix.len())
        .map(|&(_, layer)| layer)
        .unwrap()
}

/// Every module of `src/` by its path (`[]` for the crate root), with its file.
fn modules() -> BTreeMap<Vec<String>, PathBuf> {
    fn walk(dir: &Path, root: &Path, out: &mut BTreeMap<Vec<String>, PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, root, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let relative = path.strip_prefix(root).unwrap().with_extension("");
                let mut module: Vec<String> =
                    relative.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
                if module.last().is_some_and(|last| last == "mod") {
                    module.pop();
                }
                if module == ["lib"] || module == ["main"] {
                    module.clear();
                }
                out.insert(module, path);
            }
        }
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut out = BTreeMap::new();
    walk(&root, &root, &mut out);
    out
}

/// The source before its first `#[cfg(test)]` item, without `//` comments.
fn non_test_code(text: &str) -> String {
    let code = text.split("\n#[cfg(test)]").next().unwrap_or_default();
    code.lines().map(|line| line.split("//").next().unwrap_or_default()).collect::<Vec<_>>().join("\n")
}

/// The paths a `use` tree names, braces expanded: `a::{b, c::d}` is `a::b`, `a::c::d`.
fn expand(tree: &str) -> Vec<String> {
    fn parse(chars: &[char], at: &mut usize, prefix: &str, out: &mut Vec<String>) {
        let mut current = String::new();
        while *at < chars.len() {
            let c = chars[*at];
            *at += 1;
            match c {
                '{' => {
                    parse(chars, at, &format!("{prefix}{current}"), out);
                    current.clear();
                }
                '}' => break,
                ',' => {
                    if !current.is_empty() {
                        out.push(format!("{prefix}{current}"));
                    }
                    current.clear();
                }
                c if c.is_whitespace() => {}
                c => current.push(c),
            }
        }
        if !current.is_empty() {
            out.push(format!("{prefix}{current}"));
        }
    }
    // A renaming (`b as c`) keeps the path; `@` marks it through the whitespace's removal.
    let chars: Vec<char> = tree.replace(" as ", "@").chars().collect();
    let mut out = Vec::new();
    parse(&chars, &mut 0, "", &mut out);
    out.into_iter().map(|path| path.split('@').next().unwrap_or_default().to_string()).collect()
}

/// The module `path` names from `module`: its longest prefix that is a module.
fn resolve(modules: &BTreeMap<Vec<String>, PathBuf>, module: &[String], path: &str) -> Option<Vec<String>> {
    let mut parts = path.split("::").peekable();
    let mut full: Vec<String> = match *parts.peek()? {
        "crate" => {
            parts.next();
            Vec::new()
        }
        "super" => {
            let mut base = module.to_vec();
            while parts.peek() == Some(&"super") {
                parts.next();
                base.pop();
            }
            base
        }
        "self" => {
            parts.next();
            module.to_vec()
        }
        _ => return None,
    };
    full.extend(parts.map(str::to_string));
    (0..=full.len()).rev().map(|k| full[..k].to_vec()).find(|prefix| modules.contains_key(prefix))
}

/// Every module each module imports, its own ancestors (whose files declare it) left out.
fn imports() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let modules = modules();
    let mut graph = BTreeMap::new();
    for (module, file) in &modules {
        let code = non_test_code(&std::fs::read_to_string(file).unwrap());
        let mut paths = Vec::new();
        for statement in code.split(';') {
            if let Some(at) = statement.find("use ") {
                let before = &statement[..at];
                if before.trim().is_empty() || before.trim_end().ends_with("pub") || before.trim_end().ends_with(')') {
                    paths.extend(expand(&statement[at + 4..]));
                }
            }
        }
        // Paths written in place: `crate::a::b::f(...)`, `super::a::T`.
        for start in ["crate::", "super::"] {
            for (at, _) in code.match_indices(start) {
                let preceded = code[..at].chars().last().is_some_and(|c| c.is_alphanumeric() || c == '_');
                if !preceded {
                    let path: String =
                        code[at..].chars().take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':').collect();
                    paths.push(path.trim_end_matches(':').to_string());
                }
            }
        }
        let imported: BTreeSet<Vec<String>> = paths
            .iter()
            .filter_map(|path| resolve(&modules, module, path))
            .filter(|target| target != module && !module.starts_with(target))
            .collect();
        graph.insert(module.clone(), imported);
    }
    graph
}

#[test]
fn no_module_imports_from_a_layer_above_its_own() {
    let mut upward = Vec::new();
    for (module, imported) in imports() {
        for target in imported {
            if layer(&target) > layer(&module) {
                upward.push(format!(
                    "{} (layer {}) imports {} (layer {})",
                    module.join("::"),
                    layer(&module),
                    target.join("::"),
                    layer(&target)
                ));
            }
        }
    }
    assert!(upward.is_empty(), "imports that point up a layer:\n{}", upward.join("\n"));
}

#[test]
fn no_modules_import_each_other_in_a_circle() {
    let graph = imports();
    // Depth-first search; a module met again while still on the path closes a circle.
    fn visit(
        module: &Vec<String>,
        graph: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        path: &mut Vec<Vec<String>>,
        done: &mut BTreeSet<Vec<String>>,
        circles: &mut Vec<String>,
    ) {
        if done.contains(module) {
            return;
        }
        if let Some(at) = path.iter().position(|m| m == module) {
            let names: Vec<String> = path[at..].iter().chain([module]).map(|m| m.join("::")).collect();
            circles.push(names.join(" -> "));
            return;
        }
        path.push(module.clone());
        for next in graph.get(module).into_iter().flatten() {
            visit(next, graph, path, done, circles);
        }
        path.pop();
        done.insert(module.clone());
    }
    let (mut done, mut circles) = (BTreeSet::new(), Vec::new());
    for module in graph.keys() {
        visit(module, &graph, &mut Vec::new(), &mut done, &mut circles);
    }
    assert!(circles.is_empty(), "import circles:\n{}", circles.join("\n"));
}

#[test]
fn the_resolver_finds_imports_through_braces_and_supers() {
    assert_eq!(
        expand("super::{kernel::SurfacePoint, frame::{a, b as c}}"),
        ["super::kernel::SurfacePoint", "super::frame::a", "super::frame::b"]
    );
    let modules = modules();
    let kernel: Vec<String> = ["shade", "kernel"].map(String::from).to_vec();
    let point = resolve(&modules, &kernel, "super::point::SurfacePoint").unwrap();
    assert_eq!(point, ["shade", "point"]);
    assert_eq!(layer(&point), 2);
    assert_eq!(resolve(&modules, &kernel, "crate::scene::Material").unwrap(), ["scene"]);
    assert!(imports()[&kernel].contains(&point), "the kernel imports the point");
}
