//! The README and the pages under `docs/`: a README a newcomer can follow (short, in short
//! paragraphs, its measurements, design notes and test method on the pages it links), no
//! document or source file naming a file the repository does not hold, and no document citing
//! a module or item of the crate that `src/` does not hold.

use crate::util::repo_root;
use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;

/// The README's most lines: figures go to docs/FIGURES.md, not into the README.
const README_MAX_LINES: usize = 300;
/// A paragraph's most lines in the README and the docs pages written for reading through.
const PARAGRAPH_MAX_LINES: usize = 12;
/// A table cell's most words in the README and the docs pages: a cell holds one figure or a short
/// phrase, read at a glance; its detail goes into prose or a list below the table.
const CELL_MAX_WORDS: usize = 60;
/// A line's most characters in the README and the docs pages, outside code blocks: prose is
/// wrapped at about 100 characters, and a table row longer than this no longer reads as a row.
const LINE_MAX_CHARS: usize = 400;
/// The pages held to `PARAGRAPH_MAX_LINES` beside the README (FORMATS.md is a reference of
/// fields, read a field at a time).
const READ_THROUGH: [&str; 8] = [
    "docs/ARCHITECTURE.md",
    "docs/COMMANDS.md",
    "docs/DAEMON.md",
    "docs/DESIGN-NOTES.md",
    "docs/FIGURES.md",
    "docs/PACKAGING.md",
    "docs/TESTING.md",
    "docs/metrics.md",
];
/// The repository's top-level folders a path in a document may start with.
const TOP: [&str; 10] = [
    "src/",
    "python/",
    "docs/",
    "scripts/",
    "tests/",
    "crates/",
    "fixtures/",
    "systemd/",
    "udev/",
    ".ci/",
];

fn read(rel: &str) -> String {
    fs::read_to_string(repo_root().join(rel)).unwrap_or_else(|e| panic!("reads {rel}: {e}"))
}

/// Files under `dir` (relative to the repository), recursively, `target/` and `.git/` left out.
fn files_under(dir: &str) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        let Ok(entries) = fs::read_dir(dir) else { return };
        for entry in entries {
            let path = entry.expect("a readable directory").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if name == "target" || name == ".git" {
                continue;
            }
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path.strip_prefix(root).expect("under the root");
                out.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    let root = repo_root();
    let mut out = Vec::new();
    walk(&root, &root.join(dir), &mut out);
    out.sort();
    out
}

/// The markdown documents: the README and every page under docs/.
fn documents() -> Vec<String> {
    let mut docs = vec!["README.md".to_owned()];
    docs.extend(files_under("docs").into_iter().filter(|f| f.ends_with(".md")));
    docs
}

/// The text of a markdown file outside its fenced code blocks, line by line with numbers.
fn prose(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            out.push((i + 1, line));
        }
    }
    out
}

/// The longest run of lines of one paragraph (list items and table rows each count apart):
/// its length and the line it ends on.
fn longest_paragraph(text: &str) -> (usize, usize) {
    let mut longest = (0, 0);
    let mut run = 0;
    for (number, line) in prose(text) {
        let trimmed = line.trim_start();
        let item = trimmed.starts_with("- ")
            || trimmed.starts_with("* ")
            || trimmed
                .split_once(". ")
                .is_some_and(|(n, _)| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
        if trimmed.is_empty() || trimmed.starts_with('|') || trimmed.starts_with('#') {
            run = 0;
            continue;
        }
        run = if item { 1 } else { run + 1 };
        if run > longest.0 {
            longest = (run, number);
        }
    }
    longest
}

/// The cells of a markdown table row (`| a | b |`), split on each `|` no backslash escapes; none
/// for a line that is not a table row.
fn table_cells(line: &str) -> Vec<String> {
    let Some(row) = line.trim().strip_prefix('|') else {
        return Vec::new();
    };
    let mut cells = Vec::new();
    let mut cell = String::new();
    let mut escaped = false;
    for c in row.chars() {
        if c == '|' && !escaped {
            cells.push(std::mem::take(&mut cell));
        } else {
            cell.push(c);
        }
        escaped = c == '\\' && !escaped;
    }
    if !cell.trim().is_empty() {
        cells.push(cell);
    }
    cells
}

/// The first words of `text`, to name in a failure what is too long.
fn opening(text: &str) -> String {
    let words: Vec<&str> = text.split_whitespace().collect();
    let shown = words[..words.len().min(8)].join(" ");
    if words.len() > 8 { format!("{shown} ...") } else { shown }
}

/// GitHub's anchor for a heading: lower case, spaces to hyphens, other punctuation dropped.
fn anchor_of(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

fn anchors(text: &str) -> BTreeSet<String> {
    prose(text)
        .into_iter()
        .filter_map(|(_, line)| line.strip_prefix('#'))
        .map(|heading| anchor_of(heading.trim_start_matches('#')))
        .collect()
}

/// The targets of the inline links `[text](target)` of a markdown text, outside code.
fn link_targets(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (number, line) in prose(text) {
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            let after = &rest[at + 2..];
            let Some(end) = after.find(')') else { break };
            out.push((number, after[..end].to_owned()));
            rest = &after[end..];
        }
    }
    out
}

fn is_path_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || "_-./".contains(c)
}

/// The paths in `text` that start with one of the repository's top-level folders (at the
/// start of a word), with trailing punctuation cut off. Globs and placeholders are left out.
fn repository_paths(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for top in TOP {
        let mut from = 0;
        while let Some(found) = text[from..].find(top) {
            let start = from + found;
            from = start + top.len();
            let before = text[..start].chars().next_back();
            if before.is_some_and(|c| is_path_char(c) || c == '$' || c == '~') {
                continue;
            }
            let tail = &text[start..];
            let end = tail.find(|c: char| !is_path_char(c)).unwrap_or(tail.len());
            let next = tail[end..].chars().next();
            if next.is_some_and(|c| "*{<[$".contains(c)) || tail[..end].contains("..") {
                continue;
            }
            let path = tail[..end].trim_end_matches(['.', ',', ':', ';']);
            out.push(path.trim_end_matches('/').to_owned());
        }
    }
    out
}

/// The names of markdown files (`.md`) a text mentions.
fn markdown_names(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(found) = text[from..].find(".md") {
        let end = from + found + 3;
        from = end;
        if text[end..]
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            continue;
        }
        let start = text[..end - 3].rfind(|c: char| !is_path_char(c)).map_or(0, |i| i + 1);
        let name = &text[start..end];
        let base = Path::new(name).file_name().and_then(|n| n.to_str()).unwrap_or("");
        if base.len() > 3 {
            out.push(base.to_owned());
        }
    }
    out
}

#[test]
fn the_readme_is_short_and_keeps_the_test_and_install_commands() {
    let readme = read("README.md");
    let lines = readme.lines().count();
    assert!(
        lines <= README_MAX_LINES,
        "README.md has {lines} lines, more than {README_MAX_LINES}: measurements go to docs/FIGURES.md, \
         design notes to docs/DESIGN-NOTES.md, the test method to docs/TESTING.md"
    );
    for page in std::iter::once("README.md").chain(READ_THROUGH) {
        let (longest, at) = longest_paragraph(&read(page));
        assert!(
            longest <= PARAGRAPH_MAX_LINES,
            "{page}: a paragraph of {longest} lines ends on line {at} (at most {PARAGRAPH_MAX_LINES})"
        );
    }
    // The test command CI runs is the README's.
    assert!(read(".ci/run").contains("\nexec ./scripts/test\n"));
    assert!(readme.contains("\n./scripts/test    # the whole test suite"));
    for command in [
        "\nscripts/package ",
        "\nscripts/package --binary PATH --out DIR ",
        "\nsudo apt install ./target/debian/mousepose_*.deb\n",
        "\nsudo /usr/share/mousepose/nwb-env ",
        "\nsudo systemctl enable --now mousepose\n",
        "\nsystemctl status mousepose ",
        "\njournalctl -u mousepose -f ",
    ] {
        assert!(readme.contains(command), "the README lost {command:?}");
    }
    // Every docs page is linked from the README.
    for page in documents().iter().filter(|d| d.starts_with("docs/")) {
        assert!(
            readme.contains(&format!("]({page})")),
            "the README does not link {page}"
        );
    }
}

#[test]
fn no_table_cell_or_line_of_a_document_is_too_long() {
    let mut long = Vec::new();
    for doc in documents() {
        let text = read(&doc);
        for (number, line) in prose(&text) {
            let chars = line.chars().count();
            if chars > LINE_MAX_CHARS {
                long.push(format!(
                    "{doc}:{number}: a line of {chars} characters (at most {LINE_MAX_CHARS}): {}",
                    opening(line)
                ));
            }
            for (column, cell) in table_cells(line).iter().enumerate() {
                let words = cell.split_whitespace().count();
                if words > CELL_MAX_WORDS {
                    long.push(format!(
                        "{doc}:{number}: a table cell (column {}) of {words} words (at most {CELL_MAX_WORDS}): {}",
                        column + 1,
                        opening(cell)
                    ));
                }
            }
        }
    }
    assert!(
        long.is_empty(),
        "too long, outside code blocks (shorten the cell, move its detail into prose below the \
         table, or wrap the line):\n{}",
        long.join("\n")
    );
}

#[test]
fn no_document_names_a_file_that_is_not_in_the_repository() {
    let root = repo_root();
    let mut missing = Vec::new();
    // Links of the markdown documents, and the headings their anchors name.
    for doc in documents() {
        let text = read(&doc);
        let dir = Path::new(&doc).parent().unwrap_or(Path::new("")).to_owned();
        for (line, target) in link_targets(&text) {
            if target.contains("://") {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let file_text = if file.is_empty() {
                Some(text.clone())
            } else if root.join(&dir).join(file).exists() {
                fs::read_to_string(root.join(&dir).join(file)).ok()
            } else {
                missing.push(format!("{doc}:{line}: a link to {file}"));
                continue;
            };
            if !anchor.is_empty() && file_text.is_some_and(|t| !anchors(&t).contains(anchor)) {
                missing.push(format!(
                    "{doc}:{line}: a link to a heading #{anchor} {file} does not have"
                ));
            }
        }
    }
    // Paths and markdown names in the documents, the sources, the tests and the scripts.
    let mut texts: Vec<String> = documents();
    for dir in ["src", "tests", "scripts", "crates", ".ci"] {
        texts.extend(files_under(dir).into_iter().filter(|f| !f.ends_with(".png")));
    }
    let md_names: BTreeSet<String> = files_under(".")
        .into_iter()
        .filter(|f| f.ends_with(".md"))
        .filter_map(|f| Path::new(&f).file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    for rel in &texts {
        let Ok(text) = fs::read_to_string(root.join(rel)) else {
            continue;
        };
        for path in repository_paths(&text) {
            if !root.join(&path).exists() {
                missing.push(format!("{rel}: {path}"));
            }
        }
        for name in markdown_names(&text) {
            if !md_names.contains(&name) {
                missing.push(format!("{rel}: {name}"));
            }
        }
    }
    missing.sort();
    missing.dedup();
    assert!(
        missing.is_empty(),
        "files named but not in the repository:\n{}",
        missing.join("\n")
    );
}

/// The crate's modules with a file under `src/` (`a::b` for `a/b.rs` and `a/b/mod.rs`, the
/// root for `lib.rs`), each with the text of the files a cited item may be defined in: its own
/// file, and for a folder's `mod.rs` every file under the folder too (it re-exports them).
fn crate_modules() -> BTreeMap<Vec<String>, String> {
    let files: Vec<String> = files_under("src").into_iter().filter(|f| f.ends_with(".rs")).collect();
    let mut modules = BTreeMap::new();
    for file in &files {
        let rel = file.trim_start_matches("src/").trim_end_matches(".rs");
        if rel == "main" {
            continue;
        }
        let mut path: Vec<String> = rel.split('/').map(str::to_owned).collect();
        let folder = path.last().is_some_and(|p| p == "mod") || rel == "lib";
        if folder {
            path.pop();
        }
        let dir = Path::new(file)
            .parent()
            .expect("a file under src/")
            .to_string_lossy()
            .into_owned();
        let text: String = files
            .iter()
            .filter(|f| *f == file || (folder && f.starts_with(&format!("{dir}/"))))
            .map(|f| read(f))
            .collect();
        modules.insert(path, text);
    }
    modules
}

/// Whether `text` defines an item `name` (a function, type, constant, static or module).
fn defines(text: &str, name: &str) -> bool {
    [
        "fn",
        "struct",
        "enum",
        "trait",
        "type",
        "const",
        "static",
        "mod",
        "union",
        "macro_rules!",
    ]
    .iter()
    .any(|kind| mentions(text, &format!("{kind} {name}")))
}

/// Whether `text` holds `word` between non-identifier characters.
fn mentions(text: &str, word: &str) -> bool {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    text.match_indices(word)
        .any(|(at, _)| !text[..at].ends_with(ident) && !text[at + word.len()..].starts_with(ident))
}

/// The names a document cites as code paths (`a::b`, `a::b::C`, `Type::method`) in its
/// backticks outside fenced code blocks (those hold pictures and examples), with their lines;
/// command lines in backticks (`cargo ...`) left out.
fn cited_paths(text: &str) -> Vec<(usize, String)> {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let starts = |c: char| c.is_ascii_alphabetic() || c == '_';
    let mut out = Vec::new();
    for (number, line) in prose(text) {
        for span in line.split('`').skip(1).step_by(2) {
            if span.starts_with("cargo ") {
                continue;
            }
            let chars: Vec<char> = span.chars().collect();
            let mut i = 0;
            while i < chars.len() {
                if !starts(chars[i]) || (i > 0 && (ident(chars[i - 1]) || chars[i - 1] == ':')) {
                    i += 1;
                    continue;
                }
                let mut segments = Vec::new();
                loop {
                    let from = i;
                    while i < chars.len() && ident(chars[i]) {
                        i += 1;
                    }
                    segments.push(chars[from..i].iter().collect::<String>());
                    let more = chars.get(i) == Some(&':')
                        && chars.get(i + 1) == Some(&':')
                        && chars.get(i + 2).is_some_and(|&c| starts(c));
                    if !more {
                        break;
                    }
                    i += 2;
                }
                if segments.len() > 1 {
                    out.push((number, segments.join("::")));
                }
            }
        }
    }
    out
}

/// Why `path` names nothing the crate holds, if it does not: a path from a layer (or from
/// `crate::` or `mousepose::`) or from any module's name must lead through modules of `src/`
/// to an item defined there (and a name after the item must appear in the same files); a
/// path from a type (`Type::name`) needs the type defined in `src/` and the name in its files.
/// Paths from external crates, `std`, and the integration tests' modules are left alone.
fn unknown_code_name(
    path: &str,
    modules: &BTreeMap<Vec<String>, String>,
    external: &BTreeSet<String>,
) -> Option<String> {
    let segments: Vec<String> = path.split("::").map(str::to_owned).collect();
    let first = segments[0].as_str();
    if first.starts_with(|c: char| c.is_ascii_uppercase()) {
        let holders: Vec<&String> = modules.values().filter(|t| defines(t, first)).collect();
        return match segments.get(1) {
            _ if holders.is_empty() => Some(format!("no type `{first}` under src/")),
            Some(name) if !holders.iter().any(|t| mentions(t, name)) => {
                Some(format!("the files defining `{first}` do not name `{name}`"))
            }
            _ => None,
        };
    }
    let (anchors, rest): (Vec<Vec<String>>, &[String]) = if first == "crate" || first == "mousepose" {
        (vec![Vec::new()], &segments[1..])
    } else if modules.contains_key(&segments[..1]) {
        (vec![segments[..1].to_vec()], &segments[1..])
    } else {
        let ending: Vec<Vec<String>> = modules
            .keys()
            .filter(|m| m.last().is_some_and(|l| l == first))
            .cloned()
            .collect();
        if ending.is_empty() {
            let test = repo_root().join("tests").join(format!("{first}.rs"));
            if external.contains(first) || test.exists() {
                return None;
            }
            return Some(format!("no module `{first}` under src/"));
        }
        (ending, &segments[1..])
    };
    let mut why = Vec::new();
    for mut module in anchors {
        let mut at = 0;
        while at < rest.len() && modules.contains_key(&[module.clone(), vec![rest[at].clone()]].concat()) {
            module.push(rest[at].clone());
            at += 1;
        }
        // A path of modules alone names a module that is there.
        let item = rest.get(at)?;
        let text = &modules[&module];
        let name = module.join("::");
        if !defines(text, item) {
            why.push(format!("`{name}` defines no `{item}`"));
        } else if let Some(next) = rest.get(at + 1).filter(|n| !mentions(text, n)) {
            why.push(format!("`{name}` does not name `{next}`"));
        } else {
            return None;
        }
    }
    Some(why.join("; "))
}

/// The names external code is reached by in Rust paths: the package's dependencies of every
/// kind, `std` and its parts, and the C++ libraries the documents quote.
fn external_names() -> BTreeSet<String> {
    let manifest: toml::Table = read("Cargo.toml").parse().expect("Cargo.toml parses");
    let mut tables = Vec::new();
    for kind in ["dependencies", "dev-dependencies", "build-dependencies"] {
        tables.push(manifest.get(kind));
        if let Some(targets) = manifest.get("target").and_then(toml::Value::as_table) {
            tables.extend(targets.values().map(|t| t.get(kind)));
        }
    }
    let mut names: BTreeSet<String> = tables
        .into_iter()
        .flatten()
        .filter_map(toml::Value::as_table)
        .flat_map(|t| t.keys())
        .map(|k| k.replace('-', "_"))
        .collect();
    names.extend(["std", "alloc", "cv", "clippy", "rustdoc"].map(str::to_owned));
    names
}

#[test]
fn no_document_cites_a_code_name_that_is_not_in_src() {
    let modules = crate_modules();
    let external = external_names();
    let mut unknown = Vec::new();
    for doc in documents() {
        for (line, path) in cited_paths(&read(&doc)) {
            if let Some(why) = unknown_code_name(&path, &modules, &external) {
                unknown.push(format!("{doc}:{line}: `{path}`: {why}"));
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "code names cited but not in src/:\n{}",
        unknown.join("\n")
    );
}

#[test]
fn the_checks_of_this_module_see_what_they_look_for() {
    let names = markdown_names("see `docs/FORMATS.md`, README.md. and README.mdx");
    assert_eq!(names, ["FORMATS.md", "README.md"]);
    let paths = repository_paths("`src/app/run.rs`, (docs/FORMATS.md). $root/src/no tests/fuzz/ docs/*.md src/{a,b}");
    assert_eq!(paths, ["src/app/run.rs", "docs/FORMATS.md", "tests/fuzz"]);
    assert_eq!(
        anchor_of(" By hand: against `moseq2-extract`"),
        "by-hand-against-moseq2-extract"
    );
    let text = "a\nb\n\n- c\n  d\n- e\n\n```\nf\ng\n```\n";
    assert_eq!(longest_paragraph(text), (2, 2));
    let cells = table_cells(" | a | b \\| c |  d e |");
    assert_eq!(
        cells.iter().map(|c| c.trim()).collect::<Vec<_>>(),
        ["a", "b \\| c", "d e"]
    );
    assert!(table_cells("not | a row").is_empty());
    assert_eq!(opening("one two  three"), "one two three");
    assert_eq!(opening("1 2 3 4 5 6 7 8 9"), "1 2 3 4 5 6 7 8 ...");
    assert_eq!(
        link_targets("[a](FIGURES.md#c) and [d](e)"),
        [(1, "FIGURES.md#c".to_owned()), (1, "e".to_owned())]
    );
    assert_eq!(
        cited_paths("`engine::Failure`, `a::b(c)` and `cargo test x::y` `::std` `x::`\n```\n`p::q`\n```\n"),
        [(1, "engine::Failure".to_owned()), (1, "a::b".to_owned())]
    );
    // Each kind of cited name, found and not found, in a small crate of three modules.
    let modules: BTreeMap<Vec<String>, String> = [
        (vec![], "pub mod engine;\n".to_owned()),
        (
            vec!["engine".to_owned()],
            "pub enum Failure { User }\npub mod replay;\npub fn replay_with() {}\n".to_owned(),
        ),
        (
            vec!["engine".to_owned(), "replay".to_owned()],
            "pub fn replay_with() {}\n".to_owned(),
        ),
    ]
    .into();
    let external: BTreeSet<String> = ["serde".to_owned()].into();
    let unknown = |p: &str| unknown_code_name(p, &modules, &external);
    for known in [
        "engine::replay",
        "engine::Failure::User",
        "replay::replay_with",
        "crate::engine",
        "Failure::User",
        "serde::Serialize",
    ] {
        assert_eq!(unknown(known), None, "{known}");
    }
    assert_eq!(
        unknown("watch::events").as_deref(),
        Some("no module `watch` under src/")
    );
    assert_eq!(
        unknown("engine::Failures").as_deref(),
        Some("`engine` defines no `Failures`")
    );
    assert_eq!(
        unknown("engine::Failure::Work").as_deref(),
        Some("`engine` does not name `Work`")
    );
    assert_eq!(
        unknown("Failures::User").as_deref(),
        Some("no type `Failures` under src/")
    );
}

/// The alert rules of `docs/metrics.md`, as they stand there (its first YAML block after
/// "## Alert rules").
fn alert_rules() -> String {
    let text = read("docs/metrics.md");
    let section = text
        .split_once("\n## Alert rules\n")
        .expect("docs/metrics.md has its alert rules")
        .1;
    let block = section.split_once("```yaml\n").expect("a YAML block of rules").1;
    block.split_once("```").expect("the block ends").0.to_owned()
}

/// Issue 48 item 1: the alert rules of `docs/metrics.md` are what Prometheus loads
/// (`promtool check rules`), and the removal of recorded frames fires its alert while a run
/// directory moved away (the documented way of taking a live run) does not
/// (`promtool test rules`).
#[test]
fn the_alert_rules_of_metrics_md_pass_promtool() {
    let tmp = tempfile::tempdir().unwrap();
    let rules = tmp.path().join("mousepose-alerts.yml");
    fs::write(&rules, alert_rules()).unwrap();
    let promtool = |args: &[&str]| {
        let out = std::process::Command::new("promtool")
            .args(args)
            .current_dir(tmp.path())
            .output()
            .expect("promtool (Debian's prometheus package; scripts/setup.sh installs it)");
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "promtool {args:?}:\n{text}");
    };
    promtool(&["check", "rules", "mousepose-alerts.yml"]);
    let series =
        "mousepose_frames_lost_after_recording_total{job=\"mousepose\",instance=\"rig01:8470\",camera=\"depth\"";
    let tests = format!(
        "rule_files: [mousepose-alerts.yml]\n\
         evaluation_interval: 1m\n\
         tests:\n\
         \x20 - interval: 1m\n\
         \x20   input_series:\n\
         \x20     - series: '{series},reason=\"removed\"}}'\n\
         \x20       values: '0 0 0 250 250 250 250'\n\
         \x20     - series: '{series},reason=\"moved\"}}'\n\
         \x20       values: '0 400 400 400 800 800 800'\n\
         \x20   alert_rule_test:\n\
         \x20     - eval_time: 2m\n\
         \x20       alertname: MouseposeRecordedFramesRemoved\n\
         \x20       exp_alerts: []\n\
         \x20     - eval_time: 5m\n\
         \x20       alertname: MouseposeRecordedFramesRemoved\n\
         \x20       exp_alerts:\n\
         \x20         - exp_labels: {{severity: warn, job: mousepose, instance: \"rig01:8470\", camera: depth, reason: removed}}\n\
         \x20           exp_annotations:\n\
         \x20             summary: \"rig01:8470: 250 recorded depth frames removed from the disk under the daemon in 10 minutes\"\n"
    );
    fs::write(tmp.path().join("tests.yml"), tests).unwrap();
    promtool(&["test", "rules", "tests.yml"]);
}
