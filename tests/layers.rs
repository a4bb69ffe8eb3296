//! The layers of `src/` (see `src/lib.rs` and docs/ARCHITECTURE.md): imports only point
//! down, neither modules nor files import each other in a circle, and each external crate is
//! used only in the layers or modules its table row names (camera drivers in
//! `src/runtime/capture/` alone, clap in `src/app/` alone).
//!
//! Read from the source text, outside a file's `#[cfg(test)]` module (unit tests may build
//! their scenes with the synthesis engine): every `crate::layer::module` path; for the files,
//! every `use` and path from `crate::`, `super::` or `self::`, resolved to the file it leads
//! into; and every path or `use` that starts with an external crate's name.

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

/// A cycle in `graph` (its nodes in order, the first repeated at the end), if it has one:
/// depth-first search for a back edge. Edges to nodes that are not keys are left out.
fn cycle_in(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
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
            if let Some(cycle) = visit(node, graph, &mut state, &mut Vec::new()) {
                return Some(cycle);
            }
        }
    }
    None
}

#[test]
fn modules_import_each_other_in_no_cycle() {
    // Over the modules (`layer::module`) and the layers' own `mod.rs` files.
    if let Some(cycle) = cycle_in(&import_graph()) {
        panic!("modules import each other in a cycle: {}", cycle.join(" -> "));
    }
}

/// A file's module path from its place under `src/`: `a/b.rs` and `a/b/mod.rs` are `a::b`,
/// `lib.rs` is the crate's root (no segment); `main.rs` is no module of the library.
fn module_path(rel: &str) -> Option<Vec<String>> {
    let rel = rel.strip_suffix(".rs")?;
    if rel == "main" {
        return None;
    }
    let mut parts: Vec<String> = rel.split('/').map(str::to_owned).collect();
    if parts.last().is_some_and(|p| p == "mod") || rel == "lib" {
        parts.pop();
    }
    Some(parts)
}

/// Whether `line` (trimmed) starts a `use` declaration, and whether it is a re-export
/// (`pub use`, `pub(crate) use`, ...).
fn use_declaration(line: &str) -> Option<bool> {
    if line.starts_with("use ") {
        return Some(false);
    }
    let rest = line.strip_prefix("pub")?;
    let rest = match rest.strip_prefix('(') {
        Some(scoped) => &scoped[scoped.find(')')? + 1..],
        None => rest,
    };
    rest.starts_with(" use ").then_some(true)
}

/// `tree` (the text of a `use` declaration after `use`) as the paths it names:
/// `a::{b, c::{d as e, self}}` gives `a::b`, `a::c::d` and `a::c::self`.
fn use_tree_paths(prefix: &str, tree: &str, out: &mut Vec<String>) {
    let mut depth = 0;
    let mut start = 0;
    let mut items = Vec::new();
    for (at, c) in tree.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&tree[start..at]);
                start = at + 1;
            }
            _ => {}
        }
    }
    items.push(&tree[start..]);
    for item in items.into_iter().map(str::trim).filter(|i| !i.is_empty()) {
        match item.split_once('{') {
            Some((head, group)) => {
                let group = group.rsplit_once('}').map_or(group, |(g, _)| g);
                use_tree_paths(&format!("{prefix}{head}"), group, out);
            }
            None => {
                let path = item.split(" as ").next().unwrap_or(item).trim();
                out.push(format!("{prefix}{path}"));
            }
        }
    }
}

/// The paths a file's code names, each as its segments: every path of its `use` declarations
/// (re-exports left out: a folder's `mod.rs` re-exporting its files' items is their index,
/// not code of its own that uses them) and every other path (`x::y`) in its code. Unit-test
/// modules and comment lines are left out.
fn named_paths(code: &str) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    let mut rest = String::new();
    let mut lines = code.lines().map(str::trim).filter(|l| !l.starts_with("//"));
    while let Some(line) = lines.next() {
        let Some(reexport) = use_declaration(line) else {
            rest.push_str(line);
            rest.push('\n');
            continue;
        };
        let mut declaration = line.to_owned();
        while !declaration.contains(';') {
            let Some(next) = lines.next() else { break };
            declaration.push(' ');
            declaration.push_str(next);
        }
        let (tree, after) = declaration.split_once(';').unwrap_or((&declaration, ""));
        if !reexport {
            let tree = &tree[tree.find("use ").unwrap_or(0) + "use ".len()..];
            let mut paths = Vec::new();
            use_tree_paths("", tree, &mut paths);
            found.extend(paths);
        }
        rest.push_str(after);
        rest.push('\n');
    }
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let chars: Vec<(usize, char)> = rest.char_indices().collect();
    let mut i = 0;
    while i < chars.len() {
        let (at, c) = chars[i];
        let starts =
            (c.is_ascii_alphabetic() || c == '_') && (i == 0 || !(ident(chars[i - 1].1) || chars[i - 1].1 == ':'));
        if !starts {
            i += 1;
            continue;
        }
        let mut end = i;
        while end < chars.len() && (ident(chars[end].1) || chars[end].1 == ':') {
            end += 1;
        }
        let stop = chars.get(end).map_or(rest.len(), |&(e, _)| e);
        let path = rest[at..stop].trim_end_matches(':');
        if path.contains("::") {
            found.push(path.to_owned());
        }
        i = end;
    }
    found
        .into_iter()
        .map(|p| p.split("::").map(|s| s.trim().to_owned()).collect())
        .collect()
}

/// The module a path named in module `from` leads into, as far as the modules with a file
/// (`modules`) go: a path from `crate::`, `super::` or `self::`. `None` for any other path
/// (an external crate, a type, a variable, or a child module named without `self::`: see
/// [`file_graph`]).
fn resolve(from: &[String], path: &[String], modules: &BTreeSet<Vec<String>>) -> Option<Vec<String>> {
    let (mut at, rest) = match path.first()?.as_str() {
        "crate" => (Vec::new(), &path[1..]),
        "super" | "self" => {
            let mut at = from.to_vec();
            let mut rest = path;
            while let Some(first) = rest.first() {
                match first.as_str() {
                    "super" => {
                        at.pop()?;
                    }
                    "self" => {}
                    _ => break,
                }
                rest = &rest[1..];
            }
            (at, rest)
        }
        _ => return None,
    };
    for segment in rest.iter().filter(|s| *s != "self") {
        at.push(segment.clone());
        if !modules.contains(&at) {
            at.pop();
            break;
        }
    }
    Some(at)
}

/// Which file imports which: `files` are the files under `src/` (path relative to it, product
/// code), the graph's nodes their paths. A folder's `mod.rs` naming a file inside the folder
/// is not an import: the folder holds its files (its error type wraps theirs, it re-exports
/// their items, and they use its items), so a circle is between files side by side or in
/// different folders.
fn file_graph(files: &[(String, String)]) -> BTreeMap<String, BTreeSet<String>> {
    let file_of: BTreeMap<Vec<String>, &str> = files
        .iter()
        .filter_map(|(rel, _)| module_path(rel).map(|m| (m, rel.as_str())))
        .collect();
    let modules: BTreeSet<Vec<String>> = file_of.keys().cloned().collect();
    let mut graph = BTreeMap::new();
    for (rel, code) in files {
        let Some(module) = module_path(rel) else { continue };
        let imports: BTreeSet<String> = named_paths(code)
            .iter()
            .filter_map(|path| resolve(&module, path, &modules))
            .filter(|to| !to.starts_with(&module))
            .filter_map(|to| file_of.get(&to).map(|f| (*f).to_owned()))
            .collect();
        graph.insert(rel.clone(), imports);
    }
    graph
}

#[test]
fn files_import_each_other_in_no_cycle() {
    let src = repo_root().join("src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    let files: Vec<(String, String)> = paths
        .iter()
        .map(|p| {
            let rel = p.strip_prefix(&src).expect("under src/").to_string_lossy().into_owned();
            (rel, product_code(p))
        })
        .collect();
    if let Some(cycle) = cycle_in(&file_graph(&files)) {
        panic!("files import each other in a circle: {}", cycle.join(" -> "));
    }
}

#[test]
fn the_file_cycle_check_sees_a_circle() {
    let files = |d: &str| -> Vec<(String, String)> {
        [
            ("lib.rs", "pub mod a;\n"),
            ("main.rs", "use mousepose::a::b::Thing;\n"),
            (
                "a/mod.rs",
                "mod b;\nmod c;\nmod d;\npub use b::Thing;\nuse self::c::helper;\npub struct Error;\n",
            ),
            (
                "a/b.rs",
                "use super::c::{self, Other as O};\n// crate::a::d::D, in a comment\npub struct Thing;\n",
            ),
            ("a/c.rs", "pub fn helper() -> crate::a::d::D {\n    D\n}\n"),
            ("a/d.rs", d),
        ]
        .map(|(rel, code)| (rel.to_owned(), code.to_owned()))
        .to_vec()
    };
    let edges = |graph: &BTreeMap<String, BTreeSet<String>>| -> Vec<String> {
        graph
            .iter()
            .flat_map(|(from, to)| to.iter().map(move |t| format!("{from} -> {t}")))
            .collect()
    };
    let clean = file_graph(&files("use super::Error;\npub struct D;\n"));
    assert_eq!(
        edges(&clean),
        ["a/b.rs -> a/c.rs", "a/c.rs -> a/d.rs", "a/d.rs -> a/mod.rs"]
    );
    assert_eq!(cycle_in(&clean), None);
    let circle = file_graph(&files("use super::{\n    b::Thing,\n    Error,\n};\npub struct D;\n"));
    assert_eq!(
        cycle_in(&circle).map(|c| c.join(" -> ")).as_deref(),
        Some("a/b.rs -> a/c.rs -> a/d.rs -> a/b.rs")
    );
    // `self::`, `super::super::` and `crate::` resolve as far as the modules go.
    let modules: BTreeSet<Vec<String>> = [vec![], vec!["a".to_owned()], vec!["a".to_owned(), "b".to_owned()]].into();
    let path = |p: &str| p.split("::").map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(
        resolve(&path("a"), &path("crate::a::b::Thing::new"), &modules),
        Some(path("a::b"))
    );
    assert_eq!(
        resolve(&path("a::b"), &path("super::super::a::Error"), &modules),
        Some(path("a"))
    );
    assert_eq!(resolve(&path("a"), &path("self::b"), &modules), Some(path("a::b")));
    assert_eq!(resolve(&path("a"), &path("std::fs::read"), &modules), None);
}

/// The command line's shared helpers (printing, argument parsers, progress bars): every
/// command may use them.
const APP_HELPERS: [&str; 3] = ["app::output", "app::parse", "app::progress"];

#[test]
fn no_command_file_imports_another() {
    let src = repo_root().join("src");
    let commands: BTreeSet<String> = std::fs::read_dir(src.join("app"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter_map(|p| unit_of(&src, &p))
        .filter(|u| u != "app" && !APP_HELPERS.contains(&u.as_str()))
        .collect();
    let mut crossing = Vec::new();
    for (unit, imports) in import_graph() {
        if !commands.contains(&unit) {
            continue;
        }
        crossing.extend(
            imports
                .iter()
                .filter(|i| *i != &unit && commands.contains(*i))
                .map(|i| format!("{unit} -> {i}")),
        );
    }
    assert!(
        crossing.is_empty(),
        "command files importing each other (shared work belongs in src/engine/): {crossing:#?}"
    );
}

/// Engines compute: they return summaries and report progress through
/// `engine::progress::Progress`; the command line prints and draws (stdout, stderr, bars).
#[test]
fn engines_print_and_draw_nothing() {
    let src = repo_root().join("src");
    let mut files = Vec::new();
    rust_files(&src.join("engine"), &mut files);
    let printing: Vec<String> = files
        .iter()
        .filter(|p| {
            let code = product_code(p);
            [
                "print!(",
                "println!",
                "eprint!(",
                "eprintln!",
                "stdout()",
                "stderr()",
                "dbg!",
            ]
            .iter()
            .any(|m| code.contains(m))
                || uses_crate(&code, "indicatif")
        })
        .map(|p| p.display().to_string())
        .collect();
    assert!(
        printing.is_empty(),
        "engines return summaries and report progress through engine::progress::Progress; the command line prints and draws. These print or draw: {printing:?}"
    );
}

/// clap anywhere in a file, unit tests included (the table below only reads product code).
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

/// Every layer.
const ALL: &[&str] = &[
    "core",
    "io",
    "vision",
    "runtime",
    "synth",
    "training",
    "experiment",
    "engine",
    "app",
];
/// What the commands' code may use: the app and the engines it calls (`engine`, when there is
/// one).
const COMMANDS: &[&str] = &["engine", "app"];

/// Which layers (`runtime`) or modules (`runtime::capture`: that module's files) may use each
/// dependency of the package (by its name in Rust code). Every dependency has a row, so a new
/// one is placed deliberately.
const EXTERNAL: &[(&str, &[&str])] = &[
    // Camera drivers: the capture sources alone (the device listing asks them).
    ("openni2", &["runtime::capture"]),
    ("aravis_ext", &["runtime::capture"]),
    ("v4l", &["runtime::capture"]),
    // The daemon's HTTP server, metrics and frame-path channels: the runtime.
    ("tokio", &["runtime"]),
    ("axum", &["runtime"]),
    ("prometheus_client", &["runtime"]),
    // The live pose stream (ZeroMQ): its module alone; `listen` reads through its `Subscriber`.
    ("zmq", &["runtime::stream"]),
    // The LSL outlet (liblsl loaded at run time): the stream module alone.
    ("lsl_outlet", &["runtime::stream"]),
    ("crossbeam_channel", &["runtime", "engine", "app"]),
    // Processes, signals, the service manager, logging set-up, progress bars, globs, one error
    // type for everything: the commands (and the runtime's process statistics and log set-up).
    ("rustix", &["runtime", "engine", "app"]),
    ("tracing_subscriber", &["runtime", "engine", "app"]),
    ("signal_hook", COMMANDS),
    ("sd_notify", COMMANDS),
    ("tracing_journald", COMMANDS),
    ("indicatif", COMMANDS),
    ("glob", COMMANDS),
    ("anyhow", COMMANDS),
    // Depth samples read from files straight into their buffers: the readers.
    ("bytemuck", &["io", "runtime"]),
    // The command line: the app alone.
    ("clap", &["app"]),
    // OpenCV: segmentation and calibration maths, and the commands that read images.
    // Calibration's OpenCV calls (a C++ shim over Debian's OpenCV): the calibration module alone.
    ("opencv_calib", &["vision::calibrate"]),
    // CSV: the readers and writers of tables and sessions, `poses.csv`, and the batch's and
    // report's tables.
    ("csv", &["io", "runtime::sink", "engine::batch", "engine::report"]),
    // Data, maths, formats and logging: anywhere.
    ("serde", ALL),
    ("serde_json", ALL),
    ("toml", ALL),
    ("thiserror", ALL),
    ("tracing", ALL),
    ("nalgebra", ALL),
    ("rand", ALL),
    ("rand_chacha", ALL),
    ("rand_distr", ALL),
    ("rayon", ALL),
    ("zstd", ALL),
    ("png", ALL),
    ("image", ALL),
    ("crc32fast", ALL),
    // Label files kept as HDF5: their reader.
    ("hdf5_metno", &["io::paw_labels"]),
    // The models' content hashes that outputs record.
    ("sha2", &["runtime::models"]),
    ("roxmltree", ALL),
    // The paw network: its module, and its training.
    ("candle_core", &["vision::paws", "training::paws_net"]),
    // glibc's allocator told to keep what candle frees, around the paw network's training.
    ("glibc_malloc", &["engine::train"]),
    ("candle_nn", &["vision::paws", "training::paws_net"]),
    ("safe_arch", ALL),
    ("wide", ALL),
];

/// The package's dependencies (not the dev-dependencies), by their names in Rust code.
fn dependencies() -> BTreeSet<String> {
    let text = std::fs::read_to_string(repo_root().join("Cargo.toml")).expect("Cargo.toml is readable");
    let manifest: toml::Table = text.parse().expect("Cargo.toml parses");
    let mut tables = vec![manifest.get("dependencies")];
    if let Some(targets) = manifest.get("target").and_then(toml::Value::as_table) {
        tables.extend(targets.values().map(|t| t.get("dependencies")));
    }
    tables
        .into_iter()
        .flatten()
        .filter_map(toml::Value::as_table)
        .flat_map(|t| t.keys())
        .map(|k| k.replace('-', "_"))
        .collect()
}

/// Whether `code` (comment lines left out) names the crate `name`: a path that starts with it
/// (`name::`) or a `use name` (as in `use name as short;`), not a path through `crate::`,
/// `super::` or `self::` that merely has a module of the same name.
fn uses_crate(code: &str, name: &str) -> bool {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    code.lines()
        .map(str::trim_start)
        .filter(|l| !l.starts_with("//"))
        .any(|line| {
            line.match_indices(name).any(|(at, _)| {
                let before = &line[..at];
                let after = &line[at + name.len()..];
                let starts = !before.ends_with(|c: char| ident(c) || c == ':');
                let ends = !after.starts_with(ident);
                let used = after.starts_with("::") || before.split_whitespace().last() == Some("use");
                starts && ends && used
            })
        })
}

#[test]
fn crate_uses_are_found_in_paths_and_use_lines_only() {
    assert!(uses_crate("use openni2 as ni;", "openni2"));
    assert!(uses_crate("    let d = openni2::Device::open(uri)?;", "openni2"));
    assert!(uses_crate("use opencv_calib::{Error, GreyPicture};", "opencv_calib"));
    assert!(uses_crate("fn f() -> Result<(), v4l::Error> {", "v4l"));
    assert!(!uses_crate("use openni2_sys as ni;", "openni2"));
    assert!(!uses_crate("use crate::runtime::capture::openni2::list;", "openni2"));
    assert!(!uses_crate("pub mod openni2;", "openni2"));
    assert!(!uses_crate("// openni2::Device::open opens it", "openni2"));
    assert!(!uses_crate(
        "let rand = 4; rand_chacha::ChaCha8Rng::seed_from_u64(rand)",
        "rand"
    ));
    assert!(allowed("runtime::capture", &["runtime::capture"]));
    assert!(allowed("io::table", &["io", "runtime::sink"]));
    assert!(!allowed("runtime::devices", &["runtime::capture"]));
    assert!(!allowed("runtime", &["runtime::capture"]));
}

/// Whether a table row's `places` (layers, or modules `layer::module`) hold `unit`.
fn allowed(unit: &str, places: &[&str]) -> bool {
    places.iter().any(|p| *p == layer(unit) || *p == unit)
}

#[test]
fn external_crates_are_used_only_in_their_layers() {
    let deps = dependencies();
    let unplaced: Vec<&String> = deps
        .iter()
        .filter(|d| !EXTERNAL.iter().any(|(name, _)| name == d))
        .collect();
    assert!(
        unplaced.is_empty(),
        "dependencies with no row in the table of tests/layers.rs: {unplaced:?}"
    );
    let src = repo_root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut misplaced = Vec::new();
    for path in files {
        let Some(unit) = unit_of(&src, &path) else { continue };
        let code = product_code(&path);
        for (name, layers) in EXTERNAL {
            if !allowed(&unit, layers) && uses_crate(&code, name) {
                let file = path.strip_prefix(&src).expect("under src/").display().to_string();
                misplaced.push(format!("{file} uses {name}, allowed only in {layers:?}"));
            }
        }
    }
    assert!(
        misplaced.is_empty(),
        "external crates outside their layers: {misplaced:#?}"
    );
}

/// The longest a function of the product's code may be, in lines from its `fn` to its closing
/// brace: one that fits a screen reads at once.
const LONGEST_FUNCTION: usize = 120;

/// Every function of `text` with a body, as (its name, its first line, its lines), counted
/// as the project's `rustfmt` lays it out (the suite checks that it does): the body ends at
/// the first line that is only `}` at the indent its `fn` line has. A declaration without a
/// body (a trait's, an `extern` block's, ending in `;`) and a function on one line are not
/// counted.
fn function_lengths(text: &str) -> Vec<(String, usize, usize)> {
    const QUALIFIERS: [&str; 5] = ["pub ", "const ", "async ", "unsafe ", "extern \"C\" "];
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (at, line) in lines.iter().enumerate() {
        let code = line.trim_start();
        let indent = &line[..line.len() - code.len()];
        let mut rest = code;
        loop {
            if let Some(scoped) = rest.strip_prefix("pub(").and_then(|r| r.split_once(") ")) {
                rest = scoped.1;
            } else if let Some(q) = QUALIFIERS.iter().find(|q| rest.starts_with(*q)) {
                rest = &rest[q.len()..];
            } else {
                break;
            }
        }
        let Some(signature) = rest.strip_prefix("fn ") else {
            continue;
        };
        let name: String = signature
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let Some(opens) = (at..lines.len()).find(|&k| {
            let l = lines[k].trim_end();
            l.ends_with('{') || l.ends_with(';') || l.ends_with('}')
        }) else {
            continue;
        };
        let ends_at = lines[opens].trim_end();
        if !ends_at.ends_with('{') {
            continue;
        }
        let closing = format!("{indent}}}");
        if let Some(closes) = (opens + 1..lines.len()).find(|&k| lines[k].trim_end() == closing) {
            out.push((name, at + 1, closes - at + 1));
        }
    }
    out
}

#[test]
fn function_lengths_are_counted_from_fn_to_its_closing_brace() {
    let text = "fn one() -> u32 { 1 }\n\
                pub(crate) fn three(\n    a: u32,\n) -> u32 {\n    a\n}\n\
                trait T {\n    fn declared(&self);\n    fn given(&self) {\n        if true {\n        }\n    }\n}\n";
    assert_eq!(
        function_lengths(text),
        vec![("three".to_owned(), 2, 5), ("given".to_owned(), 9, 4)]
    );
}

#[test]
fn no_function_of_the_product_is_over_120_lines() {
    let root = repo_root();
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    for entry in std::fs::read_dir(root.join("crates")).expect("crates/ is readable") {
        let src = entry.expect("crates/ is readable").path().join("src");
        if src.is_dir() {
            rust_files(&src, &mut files);
        }
    }
    let mut long = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(&path).expect("a source file is readable");
        for (name, line, length) in function_lengths(&text) {
            if length > LONGEST_FUNCTION {
                let file = path.strip_prefix(&root).expect("under the repository").display();
                long.push(format!("{file}:{line}: `{name}` is {length} lines"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {LONGEST_FUNCTION} lines (split them into functions that each do one thing): {long:#?}"
    );
}
