//! The layers of `src/` (see `src/lib.rs` and docs/ARCHITECTURE.md): imports only point
//! down, modules form no cycle, and clap lives in `src/app/` alone.
//!
//! Read from the source text: every `crate::layer::module` path outside a file's
//! `#[cfg(test)]` module (unit tests may build their scenes with the synthesis engine).

use crate::util::repo_root;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Each top-level module's rank: a module may import from lower ranks only (and from itself).
const RANKS: [(&str, u32); 9] = [
    ("core", 0),
    ("io", 1),
    ("vision", 2),
    ("runtime", 3),
    ("synth", 3),
    ("training", 4),
    ("experiment", 4),
    ("engine", 5),
    ("app", 6),
];

fn rank(layer: &str) -> Option<u32> {
    RANKS.iter().find(|(l, _)| *l == layer).map(|&(_, r)| r)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src/ is readable") {
        let path = entry.expect("src/ is readable").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The code of a file without its unit-test module.
fn product_code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).expect("a source file is readable");
    match text.find("#[cfg(test)]") {
        Some(at) => text[..at].to_owned(),
        None => text,
    }
}

/// `layer::module` of a file under `src/` (`layer` alone for a layer's `mod.rs`).
fn unit_of(src: &Path, path: &Path) -> Option<String> {
    let rel = path.strip_prefix(src).expect("a file under src/");
    let parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    match parts.as_slice() {
        [file] if file == "lib" || file == "main" => None,
        [layer] | [layer, _] if parts.last().is_some_and(|p| p == "mod") => Some(layer.clone()),
        [layer] => Some(layer.clone()),
        [layer, module, ..] => Some(format!("{layer}::{module}")),
        [] => None,
    }
}

/// Every `crate::a::b` path in `code`, as `a::b` (or `a`).
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        let path: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        let mut segments = path.split("::").filter(|s| !s.is_empty());
        if let Some(layer) = segments.next() {
            match segments
                .next()
                .filter(|s| s.chars().next().is_some_and(char::is_lowercase))
            {
                Some(module) => found.insert(format!("{layer}::{module}")),
                None => found.insert(layer.to_owned()),
            };
        }
    }
    found
}

fn layer(unit: &str) -> &str {
    unit.split("::").next().unwrap_or(unit)
}

/// Every source module of the crate with the modules it imports.
fn import_graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = repo_root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in files {
        let Some(unit) = unit_of(&src, &path) else { continue };
        let imports = crate_paths(&product_code(&path));
        let entry = graph.entry(unit.clone()).or_default();
        entry.extend(imports.into_iter().filter(|i| *i != unit));
    }
    graph
}

#[test]
fn every_top_level_module_is_a_known_layer_and_src_has_few_files() {
    let src = repo_root().join("src");
    let mut top_files = Vec::new();
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            assert!(
                rank(&name).is_some(),
                "src/{name}/ is not in the layer table of tests/layers.rs"
            );
        } else {
            top_files.push(name);
        }
    }
    assert!(
        top_files.len() <= 8,
        "src/ has {} top-level files: {top_files:?}",
        top_files.len()
    );
}

#[test]
fn imports_only_point_down_the_layers() {
    let mut upward = Vec::new();
    for (unit, imports) in import_graph() {
        let own = rank(layer(&unit)).unwrap_or_else(|| panic!("{unit} is in no layer"));
        for import in &imports {
            let to = layer(import);
            if to == layer(&unit) {
                continue;
            }
            let other = rank(to).unwrap_or_else(|| panic!("{unit} imports crate::{import}, which is in no layer"));
            if other >= own {
                upward.push(format!("{unit} -> {import}"));
            }
        }
    }
    assert!(upward.is_empty(), "imports that do not point down: {upward:#?}");
}

#[test]
fn modules_import_each_other_in_no_cycle() {
    let graph = import_graph();
    // Depth-first search for a back edge, over the modules (`layer::module`) and the layers'
    // own `mod.rs` files.
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(node.to_owned(), 1);
        stack.push(node.to_owned());
        for next in graph.get(node).into_iter().flatten() {
            if !graph.contains_key(next) {
                continue;
            }
            match state.get(next.as_str()) {
                Some(1) => {
                    let from = stack.iter().position(|n| n == next).unwrap_or(0);
                    let mut cycle = stack[from..].to_vec();
                    cycle.push(next.clone());
                    return Some(cycle);
                }
                Some(_) => {}
                None => {
                    if let Some(cycle) = visit(next, graph, state, stack) {
                        return Some(cycle);
                    }
                }
            }
        }
        stack.pop();
        state.insert(node.to_owned(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for node in graph.keys() {
        if !state.contains_key(node) {
            if let Some(cycle) = visit(node, &graph, &mut state, &mut Vec::new()) {
                panic!("modules import each other in a cycle: {}", cycle.join(" -> "));
            }
        }
    }
}

/// Command files that still import another command file while their engines move to
/// `engine/` (issue 28): drop each from the list as it moves.
const NOT_YET_MOVED: [&str; 3] = ["app::batch", "app::bench", "app::run"];

#[test]
fn no_command_file_imports_another() {
    let graph = import_graph();
    let mut found = Vec::new();
    for (unit, imports) in &graph {
        if layer(unit) != "app" || unit == "app" || NOT_YET_MOVED.contains(&unit.as_str()) {
            continue;
        }
        // Only imports of another command's file count: `app` itself (`app/mod.rs`: the
        // parsers, printing, `Outcome`) is shared by all.
        for import in imports {
            if layer(import) == "app" && import != "app" && graph.contains_key(import) {
                found.push(format!("{unit} -> {import}"));
            }
        }
    }
    assert!(
        found.is_empty(),
        "command files that import another (share through app/mod.rs or an engine): {found:#?}"
    );
}

#[test]
fn clap_lives_in_the_app_folder_only() {
    let src = repo_root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let outside: Vec<String> = files
        .iter()
        .filter(|p| !p.starts_with(src.join("app")))
        .filter(|p| std::fs::read_to_string(p).unwrap().contains("clap::"))
        .map(|p| p.strip_prefix(&src).unwrap().display().to_string())
        .collect();
    assert!(outside.is_empty(), "clap is used outside src/app/: {outside:?}");
}

#[test]
fn unsafe_code_in_src_is_only_the_simd_kernel_module() {
    let src = repo_root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let with_unsafe: Vec<String> = files
        .iter()
        .filter(|f| {
            let text = std::fs::read_to_string(f).expect("a source file is readable");
            text.lines()
                .map(str::trim_start)
                .filter(|l| !l.starts_with("//"))
                .any(|l| l.contains("unsafe {") || l.contains("unsafe fn") || l.contains("allow(unsafe_code)"))
        })
        .map(|f| f.strip_prefix(&src).expect("under src/").display().to_string())
        .collect();
    assert_eq!(with_unsafe, ["vision/forest/simd.rs"]);
}
