//! The docs match the code: every method of the registry has its sections, and every link
//! between the README and the docs lands on a heading that exists.

use std::collections::BTreeSet;
use std::path::Path;

use sysid::registry::ENTRIES;

fn read(path: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(root.join(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Lines of Markdown outside fenced code blocks.
fn prose(text: &str) -> Vec<&str> {
    let mut fenced = false;
    text.lines()
        .filter(|l| {
            if l.trim_start().starts_with("```") {
                fenced = !fenced;
                return false;
            }
            !fenced
        })
        .collect()
}

/// GitHub's anchor of a heading: lower case, punctuation other than `-` and `_` dropped,
/// spaces to hyphens; a repeated anchor gets `-1`, `-2`, ….
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    for line in prose(text) {
        let Some(title) = line.strip_prefix('#').map(|t| t.trim_start_matches('#').trim()) else {
            continue;
        };
        let slug: String = title
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let mut anchor = slug.clone();
        let mut n = 0;
        while seen.contains(&anchor) {
            n += 1;
            anchor = format!("{slug}-{n}");
        }
        seen.insert(anchor);
    }
    seen
}

#[test]
fn every_method_has_a_section_in_the_docs_and_a_line_in_the_readme() {
    // docs/methods.md: a section with the method's formulas, and an entry under "What each
    // method writes and what stops it" (its history rows and stopping rules).
    let text = read("docs/methods.md");
    let (formulas, rest) = text
        .split_once("## What each method writes and what stops it")
        .expect("docs/methods.md has the section of what each method writes");
    let entries = rest.split("\n## ").next().expect("the section's text");
    for (part, what) in
        [(formulas, "a section of formulas"), (entries, "an entry of what it writes")]
    {
        let headings: Vec<&str> = prose(part).into_iter().filter(|l| l.starts_with('#')).collect();
        for entry in &ENTRIES {
            let tag = format!("`{}`", entry.name);
            let named = headings.iter().any(|h| h.contains(&tag));
            assert!(named, "docs/methods.md has no heading naming {tag} in {what}");
        }
    }
    let readme = read("README.md");
    for entry in &ENTRIES {
        let row = format!("| `{}` |", entry.name);
        assert!(readme.lines().any(|l| l.starts_with(&row)), "README's table lacks {}", entry.name);
    }
}

#[test]
fn links_between_the_docs_land_on_headings() {
    let pages = [
        "README.md",
        "docs/README.md",
        "docs/catalogue.md",
        "docs/guide.md",
        "docs/json.md",
        "docs/methods.md",
        "docs/model-files.md",
        "docs/petab.md",
        "docs/python.md",
        "docs/terminations.md",
    ];
    let mut broken = Vec::new();
    for page in pages {
        let text = read(page);
        let dir = Path::new(page).parent().unwrap_or(Path::new(""));
        for line in prose(&text) {
            // Every `](target)` of the line.
            for piece in line.split("](").skip(1) {
                let Some(target) = piece.split(')').next() else { continue };
                if target.starts_with("http") {
                    continue;
                }
                let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
                let file = if file.is_empty() {
                    page.to_string()
                } else {
                    dir.join(file).to_string_lossy().replace("docs/../", "")
                };
                let root = Path::new(env!("CARGO_MANIFEST_DIR"));
                if !root.join(&file).exists() {
                    broken.push(format!("{page}: `{target}`: no file {file}"));
                    continue;
                }
                if !anchor.is_empty()
                    && file.ends_with(".md")
                    && !anchors(&read(&file)).contains(anchor)
                {
                    broken.push(format!("{page}: `{target}`: no heading #{anchor} in {file}"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn every_path_the_docs_name_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut missing = Vec::new();
    for page in [
        "README.md",
        "docs/json.md",
        "docs/methods.md",
        "docs/model-files.md",
        "docs/terminations.md",
        "docs/catalogue.md",
        "docs/guide.md",
        "docs/petab.md",
        "docs/python.md",
    ] {
        for (i, piece) in read(page).split('`').enumerate() {
            // Odd pieces are inside backticks; placeholders such as `<name>` are not paths.
            let top = ["crates/", "tests/", "benches/", "examples/", "scripts/", "deploy/"];
            if i % 2 == 1 && top.iter().any(|t| piece.starts_with(t)) && !piece.contains('<') {
                let path = piece.split_whitespace().next().unwrap_or(piece);
                if !root.join(path).exists() {
                    missing.push(format!("{page}: {path}"));
                }
            }
        }
    }
    assert!(missing.is_empty(), "paths in the docs that do not exist:\n{}", missing.join("\n"));
}

#[test]
fn the_readmes_layout_lists_every_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = read("README.md");
    let layout = readme.split("## Layout").nth(1).expect("the README has a Layout section");
    let mut manifests = Vec::new();
    for dir in ["crates", "crates/methods"] {
        for entry in std::fs::read_dir(root.join(dir)).expect("the crates' directory") {
            let path = entry.expect("a directory entry").path();
            if path.join("Cargo.toml").exists() {
                manifests.push(path.join("Cargo.toml"));
            }
        }
    }
    assert!(manifests.len() >= 17, "found only {} crates", manifests.len());
    for manifest in manifests {
        let text = std::fs::read_to_string(&manifest).expect("a manifest");
        let name = text
            .lines()
            .find_map(|l| l.strip_prefix("name = \"").and_then(|n| n.strip_suffix('"')))
            .unwrap_or_else(|| panic!("{} has no name", manifest.display()));
        let dir = manifest.parent().and_then(|d| d.file_name()).and_then(|d| d.to_str());
        let dir = dir.expect("a crate directory");
        let line = layout.lines().find(|l| l.trim_start().starts_with(&format!("{dir}/")));
        let line = line.unwrap_or_else(|| panic!("the README's layout lacks crates/…/{dir}/"));
        assert!(line.contains(name), "the README's layout line of {dir}/ does not name {name}");
    }
}
