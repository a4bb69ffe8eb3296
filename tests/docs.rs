//! The README and the pages under `docs/`: a README a newcomer can follow (short, in short
//! paragraphs, its measurements, design notes and test method on the pages it links), and no
//! document or source file naming a file the repository does not hold.

use crate::util::repo_root;
use std::collections::BTreeSet;
use std::fs;
use std::path::Path;

/// The README's most lines: figures go to docs/FIGURES.md, not into the README.
const README_MAX_LINES: usize = 300;
/// A paragraph's most lines in the README and the docs pages written for reading through.
const PARAGRAPH_MAX_LINES: usize = 12;
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
    assert_eq!(
        link_targets("[a](FIGURES.md#c) and [d](e)"),
        [(1, "FIGURES.md#c".to_owned()), (1, "e".to_owned())]
    );
}
