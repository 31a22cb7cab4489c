//! Every crate's layers point one way and no file is part of an import circle. Read from the sources, tests
//! included, so that a convenient import cannot quietly bend the layering (the compiler accepts any direction
//! within a crate; Cargo already keeps the crates themselves in order: linkage < protocol, record < server,
//! client < harness < the root crate).
//!
//! Each crate declares its ranks below ([`LINKAGE`], [`PROTOCOL`], [`PROCESS`], [`RECORD`], [`SERVER`],
//! [`CLIENT`], [`HARNESS`], [`FAKE_DHD`], [`ROOT`]): a top-level module's rank, everything undeclared (`lib`,
//! `bench`, `cli`) at the crate's top. A file may use modules of its own rank or below. Paths are resolved as the compiler would: `use` trees (groups, nesting,
//! `self`, `as`), paths written in code, `$crate`, chains of `super::` counted from the file's module and any
//! inline `mod` it sits in, paths relative to a module's own children, and every module's `pub use`
//! re-exports, globs included (`crate::kinematics` is `crate::algorithms::kinematics`), so that a re-export
//! cannot hide an edge: a use lands on the file that defines what it names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A crate's layers: where its sources are (from the workspace root) and each top-level module's rank.
struct Layers {
    dir: &'static str,
    ranks: &'static [(&'static str, usize)],
}

/// `error` (a leaf every layer reports through) < `math` < `model` < `algorithms` (with `testing`, the
/// fixtures of the algorithms' tests: models compiled from the built-in scenes).
const LINKAGE: Layers =
    Layers { dir: "linkage/src", ranks: &[("error", 0), ("math", 1), ("model", 2), ("algorithms", 3), ("testing", 3)] };

/// The wire's shapes, a device's wrench limits and the energy books < the messages and their codec (the
/// messages' golden bytes are checked through it) < the link emulator and the room key that signs states <
/// the QUIC transport.
const PROTOCOL: Layers = Layers {
    dir: "protocol/src",
    ranks: &[
        ("shape", 0),
        ("wrench_limits", 0),
        ("passivity", 0),
        ("messages", 1),
        ("codec", 1),
        ("emulator", 2),
        ("room_key", 2),
        ("quic", 3),
    ],
};

/// What the programs ask of the operating system: real-time priority and reports, side by side.
const PROCESS: Layers = Layers { dir: "process/src", ranks: &[("realtime", 0), ("report", 0)] };

/// The record files: axis names and row types < the columns < the writer and the reader.
const RECORD: Layers =
    Layers { dir: "record/src", ranks: &[("axes", 0), ("rows", 0), ("schema", 1), ("write", 2), ("read", 2)] };

/// The sans-IO VE and access control < the gateway the driver and the view share, and the synthetic user the
/// driver's rehearsal and the benchmarks share < the view < the driver.
const SERVER: Layers = Layers {
    dir: "server/src",
    ranks: &[("access", 0), ("core", 0), ("gateway", 1), ("fleet", 1), ("synthetic", 1), ("view", 2), ("driver", 3)],
};

/// Axes < devices < the haptic core < the simulated user < the driver.
const CLIENT: Layers =
    Layers { dir: "client/src", ranks: &[("axes", 0), ("device", 1), ("core", 2), ("user", 3), ("driver", 4)] };

/// Scene arguments and number rounding < the linkage generator < charts and the load process < experiments and
/// the demo < the command line.
const ROOT: Layers = Layers {
    dir: "src",
    ranks: &[
        ("scene_arg", 0),
        ("rounding", 0),
        ("generate", 1),
        ("charts", 2),
        ("load", 2),
        ("experiments", 3),
        ("demo", 3),
        ("cli", 4),
    ],
};

/// The virtual-time harness: its tick records and its hooks on a core's calls below the session runner.
const HARNESS: Layers = Layers { dir: "harness/src", ranks: &[("record", 0), ("hooks", 0)] };

/// The fake DHD library: its plant below the exported C functions.
const FAKE_DHD: Layers = Layers { dir: "fakes/fake-dhd/src", ranks: &[("hand", 0), ("plant", 1)] };

/// The fake HD library: its plant below the exported C functions and the servo thread.
const FAKE_HD: Layers = Layers { dir: "fakes/fake-hd/src", ranks: &[("plant", 0)] };

/// The rank of a module path (its top-level segment) in `layers`.
fn rank(layers: &Layers, module: &[String]) -> usize {
    let top = layers.ranks.iter().map(|&(_, r)| r + 1).max().unwrap_or(0);
    let first = module.first().map(String::as_str);
    layers.ranks.iter().find(|(name, _)| Some(*name) == first).map_or(top, |&(_, r)| r)
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

/// What resolving a path needs to know of the whole crate: its module files, their (stripped) texts and
/// every module's re-exports.
struct Resolver {
    modules: BTreeSet<Vec<String>>,
    texts: BTreeMap<Vec<String>, String>,
    /// Module -> name it re-exports -> the absolute path that name stands for; a glob's target is
    /// filed under `*` followed by its place among the module's globs.
    reexports: BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>>,
}

impl Resolver {
    fn new(sources: &[Source]) -> Self {
        let modules = sources.iter().map(|f| f.module.clone()).collect();
        let texts = sources.iter().map(|f| (f.module.clone(), strip(&f.text))).collect();
        let mut resolver = Resolver { modules, texts, reexports: BTreeMap::new() };
        for source in sources {
            let found = resolver.reexports_of(&source.module);
            resolver.reexports.insert(source.module.clone(), found);
        }
        resolver
    }

    /// The `pub use` (and `pub(...) use`) re-exports of module `here`.
    fn reexports_of(&self, here: &[String]) -> BTreeMap<String, Vec<String>> {
        let mut map = BTreeMap::new();
        let mut globs = 0;
        for stmt in self.texts[here].split(';') {
            let Some(at) = ["pub use ", "pub(crate) use ", "pub(super) use "]
                .iter()
                .filter_map(|k| keyword_positions(stmt, k).last().map(|&at| at + k.len()))
                .max()
            else {
                continue;
            };
            let tree = stmt[at..].trim();
            for path in expand_tree(tree) {
                let Some(abs) = self.anchored(&path, here) else { continue };
                match path.last().map(String::as_str) {
                    Some("*") => {
                        map.insert(format!("*{globs}"), abs[..abs.len() - 1].to_vec());
                        globs += 1;
                    }
                    Some(name) => drop(map.insert(name.to_string(), abs)),
                    None => {}
                }
            }
            // `pub use x::y as z` names z.
            if let Some((path, alias)) = tree.rsplit_once(" as ") {
                if !path.contains('{') {
                    if let Some(abs) = self.anchored(&expand_tree(path).remove(0), here) {
                        map.insert(alias.trim().to_string(), abs);
                    }
                }
            }
        }
        map
    }

    /// The path from the crate root of `path` written in module `here`, before re-exports are followed;
    /// `None` for paths outside the crate (std, nalgebra) and for items local to the module.
    fn anchored(&self, path: &[String], here: &[String]) -> Option<Vec<String>> {
        let first = path.first()?;
        let abs = match first.as_str() {
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
            // A relative path names one of the module's children or one of its re-exports.
            name => {
                let mut p = here.to_vec();
                p.push(name.to_string());
                let reexported = self.reexports.get(here).is_some_and(|r| r.contains_key(name));
                if !self.modules.contains(&p) && !reexported {
                    return None;
                }
                p.extend_from_slice(&path[1..]);
                p
            }
        };
        Some(abs)
    }

    /// The longest prefix of `abs` that is a module file.
    fn file_prefix(&self, abs: &[String]) -> usize {
        (0..=abs.len()).rev().find(|&l| self.modules.contains(&abs[..l])).unwrap_or(0)
    }

    /// True when the text of module `module` declares an item named `name`.
    fn declares(&self, module: &[String], name: &str) -> bool {
        let Some(text) = self.texts.get(module) else { return false };
        ["fn ", "struct ", "enum ", "const ", "static ", "type ", "trait ", "mod ", "union ", "macro_rules! "]
            .iter()
            .any(|kw| {
                keyword_positions(text, kw).iter().any(|&at| {
                    let rest = &text[at + kw.len()..];
                    rest.starts_with(name)
                        && !rest[name.len()..].starts_with(|ch: char| ch.is_alphanumeric() || ch == '_')
                })
            })
    }

    /// `abs` with every re-export on its way followed to the path of what it names.
    fn follow(&self, mut abs: Vec<String>) -> Vec<String> {
        for _ in 0..16 {
            let l = self.file_prefix(&abs);
            let Some(name) = abs.get(l).cloned() else { break };
            let Some(exports) = self.reexports.get(&abs[..l]) else { break };
            let target = exports.get(&name).filter(|t| t.as_slice() != &abs[..=l]).cloned().or_else(|| {
                exports
                    .iter()
                    .filter(|(key, _)| key.starts_with('*'))
                    .map(|(_, glob)| glob)
                    .find(|glob| {
                        self.declares(glob, &name) || self.reexports.get(*glob).is_some_and(|r| r.contains_key(&name))
                    })
                    .map(|glob| {
                        let mut p = glob.clone();
                        p.push(name.clone());
                        p
                    })
            });
            let Some(mut target) = target else { break };
            target.extend_from_slice(&abs[l + 1..]);
            abs = target;
        }
        abs
    }
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
fn edges_of(from: usize, sources: &[Source], resolver: &Resolver) -> Vec<Edge> {
    let text = strip(&sources[from].text);
    let bytes: Vec<char> = text.chars().collect();
    let s: String = bytes.iter().collect();
    let line_of = |pos: usize| s[..pos].matches('\n').count() + 1;
    let modules: Vec<&Vec<String>> = sources.iter().map(|f| &f.module).collect();

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
                let Some(abs) = resolver.anchored(&path, &here).map(|abs| resolver.follow(abs)) else {
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

/// Uses that point up the ranks.
fn violations(layers: &Layers, sources: &[Source], edges: &[Edge]) -> Vec<String> {
    edges
        .iter()
        .filter(|e| rank(layers, &sources[e.to].module) > rank(layers, &sources[e.from].module))
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

/// The uses up the ranks of `layers` and the import circles among `sources`, one line each.
fn analyze(layers: &Layers, sources: &[Source]) -> (Vec<String>, Vec<String>) {
    assert!(sources.iter().any(|s| s.module.is_empty()), "no lib.rs among {} files", sources.len());
    let resolver = Resolver::new(sources);
    let edges: Vec<Edge> = (0..sources.len()).flat_map(|f| edges_of(f, sources, &resolver)).collect();
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
    (violations(layers, sources, &edges), circles)
}

/// The workspace's root directory (this test runs in the linkage crate's).
fn workspace() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the linkage crate sits in the workspace")
}

/// The library's source files under `dir` (a binary's `main.rs` is a crate of its own).
fn read_sources(dir: &Path, module: Vec<String>, out: &mut Vec<Source>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).expect("src is readable").map(|e| e.unwrap().path()).collect();
    entries.sort();
    for path in entries {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            let mut m = module.clone();
            m.push(name);
            read_sources(&path, m, out);
        } else if path.extension().is_some_and(|e| e == "rs") && !(module.is_empty() && name == "main") {
            let mut m = module.clone();
            if name != "mod" && name != "lib" {
                m.push(name);
            }
            let file = path.strip_prefix(workspace()).unwrap().display().to_string();
            out.push(Source { module: m, file, text: std::fs::read_to_string(&path).unwrap() });
        }
    }
}

/// The sources of the crate `layers` describes, after checking that each declared layer exists (a renamed
/// folder must not leave its rule checking nothing).
fn crate_sources(layers: &Layers) -> Vec<Source> {
    let mut sources = Vec::new();
    read_sources(&workspace().join(layers.dir), Vec::new(), &mut sources);
    for (layer, _) in layers.ranks {
        assert!(
            sources.iter().any(|s| s.module.first().is_some_and(|m| m == layer)),
            "{}: no module {layer}",
            layers.dir
        );
    }
    sources
}

/// Asserts that no file of the crate uses a layer above its own.
fn assert_layers_point_down(layers: &Layers) {
    let (violations, _) = analyze(layers, &crate_sources(layers));
    assert!(violations.is_empty(), "{}: uses up the layers:\n{}", layers.dir, violations.join("\n"));
}

/// Asserts that no file of the crate is part of an import circle.
fn assert_no_import_circle(layers: &Layers) {
    let (_, circles) = analyze(layers, &crate_sources(layers));
    assert!(circles.is_empty(), "{}: import circles:\n{}", layers.dir, circles.join("\n"));
}

#[test]
fn no_file_of_the_linkage_crate_uses_a_layer_above_its_own() {
    assert_layers_point_down(&LINKAGE);
}

#[test]
fn no_import_circle_in_the_linkage_crate() {
    assert_no_import_circle(&LINKAGE);
}

#[test]
fn no_file_of_the_protocol_crate_uses_a_layer_above_its_own() {
    assert_layers_point_down(&PROTOCOL);
}

#[test]
fn no_import_circle_in_the_protocol_crate() {
    assert_no_import_circle(&PROTOCOL);
}

#[test]
fn no_file_of_the_server_crate_uses_a_layer_above_its_own() {
    assert_layers_point_down(&SERVER);
}

#[test]
fn no_import_circle_in_the_server_crate() {
    assert_no_import_circle(&SERVER);
}

#[test]
fn no_file_of_the_client_crate_uses_a_layer_above_its_own() {
    assert_layers_point_down(&CLIENT);
}

#[test]
fn no_import_circle_in_the_client_crate() {
    assert_no_import_circle(&CLIENT);
}

#[test]
fn no_file_of_the_root_crate_uses_a_layer_above_its_own() {
    assert_layers_point_down(&ROOT);
}

#[test]
fn no_import_circle_in_the_root_crate() {
    assert_no_import_circle(&ROOT);
}

#[test]
fn no_file_of_the_process_record_harness_or_fake_device_crates_uses_a_layer_above_its_own() {
    for layers in [&PROCESS, &RECORD, &HARNESS, &FAKE_DHD, &FAKE_HD] {
        assert_layers_point_down(layers);
    }
}

#[test]
fn no_import_circle_in_the_process_record_harness_or_fake_device_crates() {
    for layers in [&PROCESS, &RECORD, &HARNESS, &FAKE_DHD, &FAKE_HD] {
        assert_no_import_circle(layers);
    }
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
    assert_eq!(analyze(&LINKAGE, &fixed), (vec![], vec![]), "the clean fake crate");
    // The fake crate with one more file, math/dense.rs, holding `text`.
    let with_dense = |text: &str| {
        let mut sources = fixed.to_vec();
        sources.push(src("math::dense", text));
        analyze(&LINKAGE, &sources)
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
    // Re-exports are followed to the file that defines what they name, by name and through a glob: the
    // use lands on kinematics.rs, not on algorithms/mod.rs, and a module that re-exports its children
    // makes no circle with them.
    let mut sources = fixed.to_vec();
    sources[0] = src("", &format!("{lib}\npub use algorithms::*;"));
    sources[6] = src("algorithms", "pub mod kinematics; pub mod dynamics; pub use kinematics::Jacobian;");
    sources[7] = src("algorithms::kinematics", "pub struct Jacobian; pub fn solve() { super::dynamics::g() }");
    sources[8] = src("algorithms::dynamics", "pub fn g() {}");
    assert_eq!(analyze(&LINKAGE, &sources), (vec![], vec![]), "re-exports alone");
    for text in ["use crate::algorithms::Jacobian;", "use crate::Jacobian;", "fn f() { crate::Jacobian }"] {
        let mut with = sources.clone();
        with.push(src("math::dense", text));
        let (violations, circles) = analyze(&LINKAGE, &with);
        assert!(circles.is_empty(), "{text}: {circles:?}");
        assert_eq!(violations.len(), 1, "{text}: {violations:?}");
        assert!(violations[0].ends_with("(algorithms::kinematics.rs)"), "{text}: {violations:?}");
    }
    // A circle hidden behind a re-export: dynamics uses kinematics through algorithms/mod.rs.
    sources[8] = src("algorithms::dynamics", "use super::Jacobian; pub fn g() {}");
    let (_, circles) = analyze(&LINKAGE, &sources);
    assert_eq!(circles.len(), 1, "{circles:?}");
    assert!(circles[0].contains("algorithms::dynamics.rs") && !circles[0].contains("algorithms.rs"), "{circles:?}");

    // A circle within one layer.
    let mut sources = fixed.to_vec();
    sources[8] = src("algorithms::dynamics", "use super::kinematics;");
    sources[7] = src("algorithms::kinematics", "fn f() { crate::algorithms::dynamics::g() }");
    let (_, circles) = analyze(&LINKAGE, &sources);
    assert_eq!(circles.len(), 1, "{circles:?}");
}
