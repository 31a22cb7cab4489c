//! The crate's layers point one way: `math` uses nothing of `model` or `algorithms`, `model` nothing of
//! `algorithms`, and no file is part of an import circle. Read from the sources, tests included, so that a
//! convenient import cannot quietly bend the layering (the compiler accepts any direction).
//!
//! Ranks: `error` (a leaf every layer reports through) < `math` < `model` < `algorithms` (with `testing`, the
//! fixtures of the algorithms' tests: models compiled from the built-in scenes) < the crate's top (`lib`,
//! `bench`). A file may use modules of its own rank or below. Paths are resolved as the
//! compiler would: `use` trees (groups, nesting, `self`, `as`), paths written in code, `$crate`, chains of
//! `super::` counted from the file's module and any inline `mod` it sits in, and the crate root's `pub use`
//! re-exports (`crate::kinematics` is `crate::algorithms::kinematics`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The rank of a module path (its top-level segment).
fn rank(module: &[String]) -> usize {
    match module.first().map(String::as_str) {
        Some("error") => 0,
        Some("math") => 1,
        Some("model") => 2,
        Some("algorithms") | Some("testing") => 3,
        _ => 4,
    }
}

/// One source file: its module path (`["math", "dense"]`; `[]` for lib.rs) and its text.
#[derive(Clone)]
struct Source {
    module: Vec<String>,
    file: String,
    text: String,
}

/// A use of one module by another: from the file `from` to the module file `to`, as written.
#[derive(Clone, Debug)]
struct Edge {
    from: usize,
    to: usize,
    written: String,
    line: usize,
}

/// Replaces comments, string and character literals by spaces (keeping line breaks), so that neither a
/// doc link nor a format string reads as a path or a brace.
fn strip(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let blank = |out: &mut String, ch: char| out.push(if ch == '\n' { '\n' } else { ' ' });
    let mut i = 0;
    while i < c.len() {
        let at = |i: usize, k: usize| c.get(i + k).copied().unwrap_or('\0');
        if c[i] == '/' && at(i, 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
                out.push(' ');
            }
        } else if c[i] == '/' && at(i, 1) == '*' {
            let mut depth = 0;
            loop {
                if i >= c.len() {
                    break;
                }
                if c[i] == '/' && at(i, 1) == '*' {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if c[i] == '*' && at(i, 1) == '/' {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    blank(&mut out, c[i]);
                    i += 1;
                }
            }
        } else if c[i] == 'r'
            && (at(i, 1) == '"' || (at(i, 1) == '#' && (at(i, 2) == '"' || at(i, 2) == '#')))
            && (i == 0 || !(c[i - 1].is_alphanumeric() || c[i - 1] == '_'))
        {
            // Raw string r"..." or r#"..."#.
            let mut hashes = 0;
            let mut j = i + 1;
            while c[j] == '#' {
                hashes += 1;
                j += 1;
            }
            j += 1;
            while j < c.len() && !(c[j] == '"' && (1..=hashes).all(|h| c.get(j + h) == Some(&'#'))) {
                j += 1;
            }
            let end = (j + 1 + hashes).min(c.len());
            for &ch in &c[i..end] {
                blank(&mut out, ch);
            }
            i = end;
        } else if c[i] == '"' {
            out.push(' ');
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < c.len() {
                    blank(&mut out, c[i]);
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c[i] == '\'' && (at(i, 1) == '\\' || at(i, 2) == '\'') {
            // A character literal ('x', '\n', '\u{..}'); anything else after a quote is a lifetime.
            let mut j = i + 1;
            if c[j] == '\\' {
                j += 2;
                while j < c.len() && c[j] != '\'' {
                    j += 1;
                }
            } else {
                j += 1;
            }
            for _ in i..=j.min(c.len() - 1) {
                out.push(' ');
            }
            i = j + 1;
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// Expands a `use` tree (`a::{b, c::{d as e, self}}`) into its paths, without aliases.
fn expand_tree(tree: &str) -> Vec<Vec<String>> {
    fn split_top(s: &str) -> Vec<&str> {
        let (mut parts, mut depth, mut start) = (Vec::new(), 0, 0);
        for (i, ch) in s.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    parts.push(&s[start..i]);
                    start = i + 1;
                }
                _ => {}
            }
        }
        parts.push(&s[start..]);
        parts.into_iter().map(str::trim).filter(|p| !p.is_empty()).collect()
    }
    let tree: String = tree.split_whitespace().collect::<Vec<_>>().join(" ");
    let tree = tree.trim().trim_start_matches("::");
    if let Some(open) = tree.find('{') {
        let prefix: Vec<String> =
            tree[..open].split("::").map(str::trim).filter(|s| !s.is_empty()).map(String::from).collect();
        let inner = &tree[open + 1..tree.rfind('}').expect("a closed group")];
        let mut out = Vec::new();
        for part in split_top(inner) {
            for tail in expand_tree(part) {
                let mut p = prefix.clone();
                p.extend(tail.into_iter().filter(|s| s != "self"));
                out.push(p);
            }
        }
        out
    } else {
        let path = tree.split(" as ").next().unwrap_or("");
        vec![path.split("::").map(str::trim).filter(|s| !s.is_empty()).map(String::from).collect()]
    }
}

/// The crate root's re-exports: name at the root -> the path it stands for.
fn root_reexports(lib_rs: &str) -> BTreeMap<String, Vec<String>> {
    let text = strip(lib_rs);
    let mut map = BTreeMap::new();
    for stmt in text.split(';') {
        let stmt = stmt.trim();
        if let Some(tree) = stmt.strip_prefix("pub use ") {
            let tree = tree.trim_start_matches("crate::");
            for path in expand_tree(tree) {
                if let Some(last) = path.last() {
                    map.insert(last.clone(), path.clone());
                }
            }
            // `pub use x::y as z` names z.
            if let Some((path, alias)) = tree.rsplit_once(" as ") {
                if !path.contains('{') {
                    map.insert(alias.trim().to_string(), expand_tree(path).remove(0));
                }
            }
        }
    }
    map
}

/// True when nothing of an identifier runs into position `i` from the left.
fn word_start(s: &str, i: usize) -> bool {
    i == 0 || !(s.as_bytes()[i - 1].is_ascii_alphanumeric() || s.as_bytes()[i - 1] == b'_')
}

/// Where `keyword` (with its trailing space) starts a word in `s`.
fn keyword_positions(s: &str, keyword: &str) -> Vec<usize> {
    s.match_indices(keyword).map(|(at, _)| at).filter(|&at| word_start(s, at)).collect()
}

/// Every edge from file `from`'s text to the crate's module files.
fn edges_of(from: usize, sources: &[Source], reexports: &BTreeMap<String, Vec<String>>) -> Vec<Edge> {
    let text = strip(&sources[from].text);
    let bytes: Vec<char> = text.chars().collect();
    let s: String = bytes.iter().collect();
    let line_of = |pos: usize| s[..pos].matches('\n').count() + 1;
    let modules: Vec<&Vec<String>> = sources.iter().map(|f| &f.module).collect();
    let top: BTreeSet<&str> = sources.iter().filter_map(|f| f.module.first().map(String::as_str)).collect();

    // Where each path starts, and the inline modules enclosing each position.
    let mut found: Vec<(usize, String)> = Vec::new();
    let mut use_spans: Vec<(usize, usize)> = Vec::new();
    for at in keyword_positions(&s, "use ") {
        if use_spans.last().is_some_and(|&(_, end)| at < end) {
            continue;
        }
        let end = at + s[at..].find(';').unwrap_or(s.len() - at);
        found.push((at, s[at + 4..end].to_string()));
        use_spans.push((at, end));
    }
    for anchor in ["crate::", "super::"] {
        let mut i = 0;
        while let Some(k) = s[i..].find(anchor) {
            let mut at = i + k;
            i = at + anchor.len();
            if at > 0 && s.as_bytes()[at - 1] == b'$' {
                at -= 1;
            } else if !word_start(&s, at) || s[..at].ends_with("super::") {
                continue;
            }
            if use_spans.iter().any(|&(a, b)| at >= a && at < b) {
                continue;
            }
            let len = s[at..]
                .char_indices()
                .find(|&(_, ch)| !(ch.is_alphanumeric() || ch == '_' || ch == ':' || ch == '$'))
                .map_or(s.len() - at, |(j, _)| j);
            found.push((at, s[at..at + len].trim_end_matches(':').to_string()));
        }
    }
    found.sort();

    // Inline modules: the stack at each found position.
    let mut opens: BTreeMap<usize, String> = BTreeMap::new();
    for at in keyword_positions(&s, "mod ") {
        let rest = &s[at + 4..];
        let name: String = rest.chars().take_while(|ch| ch.is_alphanumeric() || *ch == '_').collect();
        let after = rest[name.len()..].trim_start();
        if !name.is_empty() && after.starts_with('{') {
            let brace = at + 4 + name.len() + (rest[name.len()..].len() - after.len());
            opens.insert(brace, name);
        }
    }
    let mut stack: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut next = 0;
    let mut edges = Vec::new();
    for (pos, ch) in s.char_indices() {
        while next < found.len() && found[next].0 == pos {
            let (at, ref written) = found[next];
            next += 1;
            let mut here = sources[from].module.clone();
            here.extend(stack.iter().map(|(n, _)| n.clone()));
            let is_use = use_spans.iter().any(|&(a, _)| a == at);
            let paths = if is_use { expand_tree(written) } else { vec![expand_tree(written).remove(0)] };
            for path in paths {
                let Some(abs) = absolute(&path, &here, sources[from].module.is_empty(), reexports, &top) else {
                    continue;
                };
                // The longest module-file prefix is the file used.
                let to = (0..=abs.len())
                    .rev()
                    .find_map(|l| modules.iter().position(|m| m.as_slice() == &abs[..l]))
                    .expect("the root module matches");
                if to != from {
                    edges.push(Edge { from, to, written: path.join("::"), line: line_of(at) });
                }
            }
        }
        match ch {
            '{' => {
                depth += 1;
                if let Some(name) = opens.get(&pos) {
                    stack.push((name.clone(), depth));
                }
            }
            '}' => {
                if stack.last().is_some_and(|(_, d)| *d == depth) {
                    stack.pop();
                }
                depth = depth.saturating_sub(1);
            }
            _ => {}
        }
    }
    edges
}

/// The absolute path (from the crate root) of `path` written in module `here`; `None` for paths outside the
/// crate (std, nalgebra) and for items local to the module.
fn absolute(
    path: &[String],
    here: &[String],
    at_root: bool,
    reexports: &BTreeMap<String, Vec<String>>,
    top: &BTreeSet<&str>,
) -> Option<Vec<String>> {
    let first = path.first()?;
    let mut abs: Vec<String> = match first.as_str() {
        "crate" | "$crate" => path[1..].to_vec(),
        "super" => {
            let hops = path.iter().take_while(|s| *s == "super").count();
            let base = here.len().checked_sub(hops)?;
            let mut p = here[..base].to_vec();
            p.extend_from_slice(&path[hops..]);
            p
        }
        "self" => {
            let mut p = here.to_vec();
            p.extend_from_slice(&path[1..]);
            p
        }
        // At the crate root a relative path names the crate's own modules.
        name if at_root && (top.contains(name) || reexports.contains_key(name)) => path.to_vec(),
        _ => return None,
    };
    // Through the root's re-exports (repeatedly: a re-export may name another).
    for _ in 0..4 {
        match abs.first() {
            Some(name) if !top.contains(name.as_str()) => match reexports.get(name) {
                Some(target) if target.first() != Some(name) => {
                    let mut p = target.clone();
                    p.extend_from_slice(&abs[1..]);
                    abs = p;
                }
                _ => break,
            },
            _ => break,
        }
    }
    Some(abs)
}

/// Uses that point up the ranks.
fn violations(sources: &[Source], edges: &[Edge]) -> Vec<String> {
    edges
        .iter()
        .filter(|e| rank(&sources[e.to].module) > rank(&sources[e.from].module))
        .map(|e| format!("{}:{} uses {} ({})", sources[e.from].file, e.line, e.written, sources[e.to].file))
        .collect()
}

/// The import circles: strongly connected sets of more than one file (Tarjan).
fn circles(n: usize, edges: &[Edge]) -> Vec<Vec<usize>> {
    let mut next: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); n];
    for e in edges {
        next[e.from].insert(e.to);
    }
    struct State {
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        counter: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(v: usize, next: &[BTreeSet<usize>], st: &mut State) {
        st.index[v] = Some(st.counter);
        st.low[v] = st.counter;
        st.counter += 1;
        st.stack.push(v);
        st.on_stack[v] = true;
        for &w in &next[v] {
            match st.index[w] {
                None => {
                    visit(w, next, st);
                    st.low[v] = st.low[v].min(st.low[w]);
                }
                Some(iw) if st.on_stack[w] => st.low[v] = st.low[v].min(iw),
                _ => {}
            }
        }
        if Some(st.low[v]) == st.index[v] {
            let mut set = Vec::new();
            while let Some(w) = st.stack.pop() {
                st.on_stack[w] = false;
                set.push(w);
                if w == v {
                    break;
                }
            }
            if set.len() > 1 {
                set.sort();
                st.out.push(set);
            }
        }
    }
    let mut st = State {
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        counter: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if st.index[v].is_none() {
            visit(v, &next, &mut st);
        }
    }
    st.out
}

fn analyze(sources: &[Source]) -> (Vec<String>, Vec<String>) {
    let lib = sources.iter().find(|s| s.module.is_empty()).expect("lib.rs");
    let reexports = root_reexports(&lib.text);
    let edges: Vec<Edge> = (0..sources.len()).flat_map(|f| edges_of(f, sources, &reexports)).collect();
    let circles = circles(sources.len(), &edges)
        .into_iter()
        .map(|set| {
            let within: Vec<String> = edges
                .iter()
                .filter(|e| set.contains(&e.from) && set.contains(&e.to))
                .map(|e| format!("{}:{} -> {}", sources[e.from].file, e.line, e.written))
                .collect();
            within.join("; ")
        })
        .collect();
    (violations(sources, &edges), circles)
}

fn read_sources(dir: &Path, module: Vec<String>, out: &mut Vec<Source>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).expect("src is readable").map(|e| e.unwrap().path()).collect();
    entries.sort();
    for path in entries {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            let mut m = module.clone();
            m.push(name);
            read_sources(&path, m, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let mut m = module.clone();
            if name != "mod" && name != "lib" {
                m.push(name);
            }
            let file = path.strip_prefix(env!("CARGO_MANIFEST_DIR")).unwrap().display().to_string();
            out.push(Source { module: m, file, text: std::fs::read_to_string(&path).unwrap() });
        }
    }
}

fn crate_sources() -> Vec<Source> {
    let mut sources = Vec::new();
    read_sources(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"), Vec::new(), &mut sources);
    sources
}

#[test]
fn no_file_uses_a_layer_above_its_own() {
    let sources = crate_sources();
    for layer in ["math", "model", "algorithms"] {
        assert!(sources.iter().any(|s| s.module.first().is_some_and(|m| m == layer)), "no {layer}/ folder");
    }
    let (violations, _) = analyze(&sources);
    assert!(violations.is_empty(), "uses up the layers:\n{}", violations.join("\n"));
}

#[test]
fn no_import_circle_among_the_files() {
    let (_, circles) = analyze(&crate_sources());
    assert!(circles.is_empty(), "import circles:\n{}", circles.join("\n"));
}

/// The checker itself: a small fake crate with one use of each kind that must be caught, and the uses
/// that must not be.
#[test]
fn the_checker_catches_every_way_of_writing_an_upward_use() {
    let src = |module: &str, text: &str| Source {
        module: module.split("::").filter(|s| !s.is_empty()).map(String::from).collect(),
        file: format!("{module}.rs"),
        text: text.to_string(),
    };
    let lib = "pub mod math; pub mod model; pub mod algorithms; pub mod error;\n\
               pub use algorithms::{kinematics, dynamics::{forward_dynamics as fd}};\n\
               pub use model::Model;\npub use math::space::Planar;";
    let fixed = [
        src("", lib),
        src("error", ""),
        src("math", "pub mod dense; pub mod space;"),
        src("math::space", "pub struct Planar;"),
        src("model", "pub struct Model; pub mod data;"),
        src("model::data", "use crate::math::space::Planar; use crate::error;"),
        src("algorithms", "pub mod kinematics; pub mod dynamics;"),
        src("algorithms::kinematics", "use crate::model::{data, Model};"),
        src("algorithms::dynamics", "use super::kinematics; pub fn forward_dynamics() {}"),
    ];
    assert_eq!(analyze(&fixed), (vec![], vec![]), "the clean fake crate");
    // The fake crate with one more file, math/dense.rs, holding `text`.
    let with_dense = |text: &str| {
        let mut sources = fixed.to_vec();
        sources.push(src("math::dense", text));
        analyze(&sources)
    };
    let upward = [
        "use crate::model::Model;",
        "use crate::{math::space, model::data::{self}};",
        "fn f() { let _ = crate::algorithms::kinematics::x(); }",
        "use crate::kinematics;",
        "use crate::fd;",
        "use crate::Model;",
        "use super::super::model::data;",
        "mod tests { use super::super::super::algorithms::dynamics; }",
        "macro_rules! m { () => { $crate::model::Model } }",
    ];
    for text in upward {
        let (violations, _) = with_dense(text);
        assert_eq!(violations.len(), 1, "{text}: {violations:?}");
    }
    let harmless = [
        "// use crate::model::Model;",
        "/// [`crate::algorithms::kinematics`]\nfn f() {}",
        "fn f() { let _ = \"crate::model::Model {\"; let _ = '{'; }",
        "use crate::math::space::Planar; use super::space::Planar as P; use nalgebra::DVector;",
        "mod tests { use super::*; use crate::math::space; }",
    ];
    for text in harmless {
        assert_eq!(with_dense(text), (vec![], vec![]), "{text}");
    }
    // A circle within one layer.
    let mut sources = fixed.to_vec();
    sources[8] = src("algorithms::dynamics", "use super::kinematics;");
    sources[7] = src("algorithms::kinematics", "fn f() { crate::algorithms::dynamics::g() }");
    let (_, circles) = analyze(&sources);
    assert_eq!(circles.len(), 1, "{circles:?}");
}
