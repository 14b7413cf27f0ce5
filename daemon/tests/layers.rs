//! The daemon's modules point one way: link -> port -> engine -> master ->
//! api -> lifecycle (config and realtime below them all). This reads every
//! file under `daemon/src`, collects which top-level modules each one uses
//! (`crate::<module>` outside comments), and fails on any import circle,
//! naming it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The top-level module a file belongs to (`api/sdo.rs` -> `api`).
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).ok()?;
    let first = rel.components().next()?.as_os_str().to_str()?;
    let name = first.strip_suffix(".rs").unwrap_or(first);
    (!matches!(name, "lib" | "main" | "bin")).then(|| name.to_string())
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `crate::<name>` paths in code (comment lines left out).
fn uses(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in text.lines().map(str::trim_start).filter(|l| !l.starts_with("//")) {
        let mut rest = line;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let name: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            if !name.is_empty() {
                out.insert(name);
            }
        }
    }
    out
}

#[test]
fn no_import_circle_between_the_daemons_modules() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let Some(m) = module_of(&src, f) else { continue };
        let text = std::fs::read_to_string(f).unwrap();
        let deps = graph.entry(m.clone()).or_default();
        deps.extend(uses(&text).into_iter().filter(|d| *d != m));
    }
    assert!(graph.len() >= 10, "the modules were not found: {graph:?}");
    if let Some(cycle) = first_circle(&graph) {
        panic!("import circle: {}\n(the module graph: {graph:#?})", cycle.join(" -> "));
    }
    // The layers the brief names, checked as edges that must not exist.
    for (low, high) in
        [("engine", "master"), ("master", "api"), ("engine", "api"), ("metrics", "api"), ("config", "api")]
            .into_iter()
            // Front ends beside each other, none under the master.
            .chain([("sparkplug", "api"), ("api", "sparkplug"), ("gateway", "api"), ("api", "gateway")])
            .chain([
                ("sparkplug", "gateway"),
                ("gateway", "sparkplug"),
                ("metrics", "sparkplug"),
                ("metrics", "gateway"),
            ])
            .chain([("master", "sparkplug"), ("master", "gateway"), ("engine", "sparkplug")])
            .chain([("opcua", "api"), ("api", "opcua"), ("opcua", "sparkplug"), ("sparkplug", "opcua")])
            .chain([("opcua", "gateway"), ("metrics", "opcua"), ("master", "opcua"), ("engine", "opcua")])
            .chain([("web", "api"), ("api", "web"), ("master", "web"), ("engine", "web"), ("web", "opcua")])
            .chain([("opcua", "web"), ("web", "sparkplug"), ("web", "gateway"), ("web", "metrics")])
    {
        assert!(!graph[low].contains(high), "{low} uses {high}: layers point one way");
    }
}

/// The daemon's front ends: each serves the master's domain in its own
/// protocol.
const FRONT_ENDS: [&str; 6] = ["api", "sparkplug", "gateway", "metrics", "opcua", "web"];

/// What a front-end file reaches past the master: the engine
/// (`crate::engine`), the chip's codec (`ecmxf_wire`), or another front end
/// (`crate::api` from `sparkplug/`...). Comment lines are left out.
fn front_end_offences(src: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for front in FRONT_ENDS {
        let mut files = Vec::new();
        let dir = src.join(front);
        if dir.is_dir() {
            rust_files(&dir, &mut files);
        } else if src.join(format!("{front}.rs")).is_file() {
            files.push(src.join(format!("{front}.rs")));
        }
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            let name = f.strip_prefix(src).unwrap().display().to_string();
            let used = uses(&text);
            for other in FRONT_ENDS.iter().filter(|o| **o != front).chain(&["engine"]) {
                if used.contains(*other) {
                    out.push(format!("{name} uses crate::{other}"));
                }
            }
            let code = text.lines().map(str::trim_start).filter(|l| !l.starts_with("//"));
            if code.clone().any(|l| l.contains("ecmxf_wire")) {
                out.push(format!("{name} uses ecmxf_wire"));
            }
        }
    }
    out
}

/// Front ends reach the chip through the master alone: no file under
/// `api/`, `sparkplug/`, `gateway/` or `metrics/` names `crate::engine`,
/// the wire crate, or another front end; what they need the master
/// re-exports or does for them (a new front end gets the same one door).
#[test]
fn front_ends_import_the_master_not_the_engine_the_wire_or_each_other() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut api = Vec::new();
    rust_files(&src.join("api"), &mut api);
    assert!(api.len() >= 10, "the api files were not found");
    let offences = front_end_offences(&src);
    assert!(offences.is_empty(), "front-end files that reach past the master: {offences:#?}");
}

/// The front-end check can fail: a planted file of each kind of offence
/// is named.
#[test]
fn a_front_end_reaching_past_the_master_is_found() {
    let dir = std::env::temp_dir().join(format!("ecmxf-front-ends-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("api")).unwrap();
    std::fs::create_dir_all(dir.join("gateway")).unwrap();
    std::fs::write(
        dir.join("api/ok.rs"),
        "// ecmxf_wire in a comment
use crate::master::Master;
",
    )
    .unwrap();
    assert_eq!(front_end_offences(&dir), Vec::<String>::new());
    std::fs::write(
        dir.join("api/sdo.rs"),
        "use ecmxf_wire::payload::sdo::SdoAbortCode;
",
    )
    .unwrap();
    std::fs::write(
        dir.join("gateway/mod.rs"),
        "use crate::engine::slot::Job;
use crate::api::Context;
",
    )
    .unwrap();
    let found = front_end_offences(&dir);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(
        found,
        ["api/sdo.rs uses ecmxf_wire", "gateway/mod.rs uses crate::api", "gateway/mod.rs uses crate::engine"],
    );
}

/// `api::Context` holds what the gRPC front end alone needs (roles, its
/// streams' stop, its metrics): the domain's state (leases, their TTL)
/// is the master's, shared by every front end.
#[test]
fn the_api_context_holds_no_domain_state() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/api/mod.rs");
    let text = std::fs::read_to_string(src).unwrap();
    let start = text.find("struct Context").expect("api::Context");
    let body = &text[start..start + text[start..].find("\n}").unwrap()];
    for field in ["lease", "Leases", "image", "shadow"] {
        assert!(
            !body.lines().filter(|l| !l.trim_start().starts_with("//")).any(|l| l.contains(field)),
            "api::Context holds {field}: the master owns it"
        );
    }
}

/// The items a `mod.rs` / `lib.rs` defines itself (struct, enum, fn,
/// const, static, type, trait, union; `pub` or not): the lines that start
/// one at the file's top level. `mod` and `use` lines define nothing here.
fn items_defined(text: &str) -> BTreeSet<String> {
    let ident = |t: &str| t.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect::<String>();
    let mut out = BTreeSet::new();
    for line in text.lines().filter(|l| !l.starts_with(char::is_whitespace) && !l.starts_with("//")) {
        let mut words = line.split_whitespace().peekable();
        while let Some(w) = words.next() {
            match w {
                _ if w == "pub" || w.starts_with("pub(") => {}
                "unsafe" | "async" | "extern" | "default" | "\"C\"" => {}
                // `const fn f`: the item is the fn.
                "const" if words.peek() == Some(&"fn") => {}
                "static" if words.peek() == Some(&"mut") => {
                    words.next();
                    out.extend(words.next().map(ident).filter(|n| !n.is_empty()));
                    break;
                }
                "struct" | "enum" | "fn" | "const" | "static" | "type" | "trait" | "union" => {
                    out.extend(words.next().map(ident).filter(|n| !n.is_empty()));
                    break;
                }
                _ => break,
            }
        }
    }
    out
}

/// Whether `code` names one of `items` through one of `prefixes`
/// (`super::Item`, `super::{Item, ..}`, `crate::engine::Item::Variant`).
fn names_an_item(code: &str, prefixes: &[&str], items: &BTreeSet<String>) -> bool {
    let ident = |t: &str| t.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect::<String>();
    for prefix in prefixes {
        for (i, _) in code.match_indices(prefix) {
            // `crate::super::` is no path; `x::super::` is not this folder's.
            if code[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let rest = &code[i + prefix.len()..];
            let first_segments: Vec<String> = if let Some(group) = rest.strip_prefix('{') {
                // The group's elements at its own depth: `A`, `B as C`, `x::D`.
                let (mut depth, mut start, mut elements) = (0usize, 0usize, Vec::new());
                for (j, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => {
                            elements.push(&group[start..j]);
                            break;
                        }
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            elements.push(&group[start..j]);
                            start = j + 1;
                        }
                        _ => {}
                    }
                }
                elements.iter().map(|e| ident(e.trim())).collect()
            } else {
                vec![ident(rest)]
            };
            if first_segments.iter().any(|n| items.contains(n)) {
                return true;
            }
        }
    }
    false
}

/// Whether a `mod.rs` / `lib.rs` names its child `child`: `child::x`
/// (a path or a `use child::x` re-export), `self::child::x`, or the
/// folder's prefix. `mod child;` declares it and is no use.
fn names_child(code: &str, child: &str, prefix: &str) -> bool {
    let path = format!("{child}::");
    code.match_indices(&path).any(|(i, _)| {
        let before = &code[..i];
        before.ends_with("self::")
            || before.ends_with(prefix)
            || !before.ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':')
    })
}

/// The file-level modules of one folder (`engine/`, the wire crate) and
/// which of them each names: `super::x` from a file directly in it,
/// `prefix x` (`crate::engine::x`) from anywhere in it. A subfolder is one
/// module. The folder's `mod.rs` (`lib.rs` at a crate root) is a module
/// too: a file that names an item it defines (`super::Item`, `prefix
/// Item`) uses it, and it uses the files it names (`child::x`, `use
/// child::x` re-exports), so a circle through it is found like any other.
fn file_graph(dir: &Path, prefix: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut nodes: BTreeMap<String, String> = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = p.file_stem().unwrap().to_string_lossy().into_owned();
        if matches!(name.as_str(), "mod" | "lib" | "main") {
            continue;
        }
        let text = if p.is_dir() {
            let mut files = Vec::new();
            rust_files(&p, &mut files);
            // Inside a subfolder, `super::` is that subfolder itself:
            // only `super::super::x` and the prefix reach out.
            files
                .iter()
                .map(|f| {
                    std::fs::read_to_string(f).unwrap().replace("super::super::", "@@::").replace("super::", "self::")
                })
                .collect::<Vec<_>>()
                .join("\n")
                .replace("@@::", "super::")
        } else if p.extension().is_some_and(|x| x == "rs") {
            std::fs::read_to_string(&p).unwrap()
        } else {
            continue;
        };
        nodes.insert(name, text);
    }
    let mut graph = BTreeMap::new();
    for (name, text) in &nodes {
        let code: String = text.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
        let deps: BTreeSet<String> = nodes
            .keys()
            .filter(|other| *other != name)
            .filter(|other| {
                [
                    format!("super::{other}::"),
                    format!("super::{other}}}"),
                    format!("{prefix}{other}::"),
                    format!("{prefix}{other}}}"),
                ]
                .iter()
                .any(|pat| code.contains(pat.as_str()))
                    || code.contains(&format!("super::{{{other}"))
                    || code.contains(&format!("super::{other};"))
            })
            .cloned()
            .collect();
        graph.insert(name.clone(), deps);
    }
    let parent = ["mod", "lib"].into_iter().find(|p| dir.join(format!("{p}.rs")).is_file());
    if let Some(parent) = parent {
        let text = std::fs::read_to_string(dir.join(format!("{parent}.rs"))).unwrap();
        let items = items_defined(&text);
        for (name, text) in &nodes {
            let code: String =
                text.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
            if names_an_item(&code, &["super::", prefix], &items) {
                graph.get_mut(name).unwrap().insert(parent.to_string());
            }
        }
        let code: String = text.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
        let deps = nodes.keys().filter(|child| names_child(&code, child, prefix)).cloned().collect();
        graph.insert(parent.to_string(), deps);
    }
    graph
}

/// The first import circle found by a depth-first search, as a path.
fn first_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut cycle = path[i..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_string());
        for d in graph.get(m).into_iter().flatten() {
            if let Some(c) = visit(d, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|m| visit(m, graph, &mut Vec::new(), &mut done))
}

/// Folders whose `mod.rs` / `lib.rs` and one of their files still use
/// each other (found once `mod.rs` counted as a module), left to their
/// owners: here their other files are still checked with `mod.rs` left
/// out, and an entry that no longer has such a circle fails the test, so
/// the list only shrinks.
const MOD_CIRCLES_LEFT: [&str; 7] = [
    "daemon/src/master",
    "daemon/src/api",
    "daemon/src/link",
    "daemon/src/sparkplug",
    "wire/src/payload",
    "devices/src/eni",
    "sim/src/chip",
];

/// No circle between the files of any folder of the workspace's crates
/// (bring-up and the held outputs once used each other in the engine;
/// framing and header in the wire crate; the engine's running loop and
/// its `mod.rs`). Each folder is checked on its own: its files, its
/// subfolders as one module each, and its `mod.rs` (see [`file_graph`]).
#[test]
fn no_import_circle_between_the_files_of_any_folder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut checked = Vec::new();
    let mut circles = Vec::new();
    for krate in ["daemon", "wire", "devices", "sim", "client"] {
        let src = root.join(krate).join("src");
        let mut dirs = vec![src.clone()];
        let mut i = 0;
        while i < dirs.len() {
            for e in std::fs::read_dir(&dirs[i]).unwrap().flatten() {
                if e.path().is_dir() {
                    dirs.push(e.path());
                }
            }
            i += 1;
        }
        for dir in dirs {
            // The crate root's files are top-level modules: named as
            // `crate::x`, checked for the daemon by the test above.
            let rel = dir.strip_prefix(&src).unwrap();
            let prefix: String = rel.components().map(|c| format!("{}::", c.as_os_str().to_string_lossy())).collect();
            let mut graph = file_graph(&dir, &format!("crate::{prefix}"));
            let folder = format!("{krate}/src/{}", rel.display());
            let folder = folder.trim_end_matches('/');
            if MOD_CIRCLES_LEFT.contains(&folder) {
                assert!(first_circle(&graph).is_some(), "{folder}: no circle left; take it off MOD_CIRCLES_LEFT");
                for parent in ["mod", "lib"] {
                    graph.remove(parent);
                    for deps in graph.values_mut() {
                        deps.remove(parent);
                    }
                }
            }
            if let Some(c) = first_circle(&graph) {
                circles.push(format!("{folder}: {}", c.join(" -> ")));
            }
            checked.push(dir);
        }
    }
    assert!(circles.is_empty(), "import circles: {circles:#?}");
    let engine = checked.iter().any(|d| d.ends_with("daemon/src/engine"));
    assert!(checked.len() >= 15 && engine, "folders not found: {checked:?}");
}

/// Outside the engine, only the master names it: every other part of the
/// daemon (metrics, the service, the probe, the API) takes what it needs
/// from the master's re-exports, so the engine's insides can change
/// behind one door.
#[test]
fn only_the_master_names_the_engine() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let offenders: Vec<String> = files
        .iter()
        .filter(|f| !f.starts_with(src.join("engine")) && !f.starts_with(src.join("master")))
        .filter(|f| uses(&std::fs::read_to_string(f).unwrap()).contains("engine"))
        .map(|f| f.strip_prefix(&src).unwrap().display().to_string())
        .collect();
    assert!(offenders.is_empty(), "files outside engine/ and master/ that name crate::engine: {offenders:?}");
}

/// The checks above can fail: a folder whose files use each other, by
/// `super::` or by the crate path, is found to have a circle.
#[test]
fn a_circle_between_two_files_is_found() {
    let dir = std::env::temp_dir().join(format!("ecmxf-layers-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::write(dir.join("a.rs"), "use super::b::Thing;\n").unwrap();
    std::fs::write(dir.join("b.rs"), "// use super::a (a comment is no import)\nfn f() {}\n").unwrap();
    std::fs::write(dir.join("sub/mod.rs"), "use crate::x::a::Other;\n").unwrap();
    let graph = file_graph(&dir, "crate::x::");
    assert_eq!(first_circle(&graph), None, "{graph:?}");
    std::fs::write(dir.join("b.rs"), "use crate::x::sub::Inner;\n").unwrap();
    let graph = file_graph(&dir, "crate::x::");
    let circle = first_circle(&graph).expect("a -> b -> sub -> a");
    assert_eq!(circle.len(), 4, "{circle:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A folder's `mod.rs` counts too: a file that names an item `mod.rs`
/// defines, while `mod.rs` names that file, closes a circle; naming a
/// sibling's item of the same name does not.
#[test]
fn a_circle_through_mod_rs_is_found() {
    let dir = std::env::temp_dir().join(format!("ecmxf-layers-mod-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("mod.rs"),
        "//! pub struct InAComment;\nmod a;\nmod b;\npub(crate) use a::Thing;\n\n#[derive(Debug)]\n\
         pub(crate) struct Shared;\nconst fn helper() {}\nstatic mut COUNT: u8 = 0;\nimpl Shared {\n    fn method() {}\n}\n",
    )
    .unwrap();
    let items: Vec<String> = items_defined(&std::fs::read_to_string(dir.join("mod.rs")).unwrap()).into_iter().collect();
    assert_eq!(items, ["COUNT", "Shared", "helper"]);
    std::fs::write(dir.join("a.rs"), "pub(crate) struct Thing;\nuse super::b::Shared;\n").unwrap();
    std::fs::write(dir.join("b.rs"), "// use super::Shared (a comment is no import)\npub(crate) struct Shared;\n")
        .unwrap();
    let graph = file_graph(&dir, "crate::x::");
    assert_eq!(first_circle(&graph), None, "{graph:?}");
    assert!(graph["mod"].contains("a") && !graph["a"].contains("mod"), "{graph:?}");
    for planted in ["use super::Shared;\n", "use super::{b, Shared as S};\n", "fn f() { crate::x::helper() }\n"] {
        std::fs::write(dir.join("a.rs"), planted).unwrap();
        let graph = file_graph(&dir, "crate::x::");
        let circle = first_circle(&graph).unwrap_or_else(|| panic!("a -> mod -> a from {planted:?}: {graph:?}"));
        assert_eq!(circle.len(), 3, "{circle:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
