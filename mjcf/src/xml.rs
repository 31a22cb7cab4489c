//! The model's XML as an owned tree: every element keeps its file and line (roxmltree keeps text
//! positions), `<include file=".."/>` is replaced by the included file's top-level children, and attributes
//! are plain strings parsed on use, so a bad number is reported where it was written.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::MjcfError;

/// How deep includes may nest before the reader assumes a cycle.
const MAX_INCLUDE_DEPTH: usize = 16;

/// One XML element with its attributes, children and source position.
#[derive(Clone, Debug)]
pub struct Element {
    /// The tag.
    pub tag: String,
    /// Attributes in file order.
    pub attrs: Vec<(String, String)>,
    /// Child elements (text and comments dropped).
    pub children: Vec<Element>,
    /// The file the element was written in.
    pub file: Arc<str>,
    /// Its line (1-based).
    pub line: u32,
}

impl Element {
    /// The attribute `key`, if present.
    pub fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// The children with tag `tag`.
    pub fn children_named<'a>(&'a self, tag: &'a str) -> impl Iterator<Item = &'a Element> + 'a {
        self.children.iter().filter(move |c| c.tag == tag)
    }

    /// `tag` or `tag 'name'`, for messages.
    pub fn label(&self) -> String {
        match self.attr("name") {
            Some(n) => format!("{} '{n}'", self.tag),
            None => self.tag.clone(),
        }
    }

    /// An error at this element.
    pub fn error(&self, problem: impl Into<String>) -> MjcfError {
        MjcfError::Invalid {
            file: self.file.to_string(),
            line: self.line,
            element: self.label(),
            problem: problem.into(),
        }
    }

    /// The numbers of attribute `key` (whitespace-separated), or `None` when absent.
    pub fn numbers(&self, key: &str) -> Result<Option<Vec<f64>>, MjcfError> {
        let Some(text) = self.attr(key) else { return Ok(None) };
        text.split_whitespace()
            .map(|s| match s.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(self.error(format!("{key}=\"{text}\": '{s}' is not a finite number"))),
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }

    /// Exactly `N` numbers of attribute `key`, or `None` when absent.
    pub fn fixed<const N: usize>(&self, key: &str) -> Result<Option<[f64; N]>, MjcfError> {
        match self.numbers(key)? {
            None => Ok(None),
            Some(v) => <[f64; N]>::try_from(v.as_slice())
                .map(Some)
                .map_err(|_| self.error(format!("{key} needs {N} numbers, got {}", v.len()))),
        }
    }

    /// One number of attribute `key`, or `default` when absent.
    pub fn number(&self, key: &str, default: f64) -> Result<f64, MjcfError> {
        Ok(self.fixed::<1>(key)?.map_or(default, |[x]| x))
    }
}

/// Reads `path` and the files it includes into one tree rooted at `<mujoco>`.
pub fn read_file(path: &Path) -> Result<Element, MjcfError> {
    let file = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| MjcfError::Io { file: file.clone(), message: e.to_string() })?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse(&text, &file, &dir, 0)
}

/// Parses model text; `file` names it in errors and `dir` is where its includes are looked up (MuJoCo
/// resolves every include relative to the main model's folder).
pub fn read_str(text: &str, file: &str, dir: &Path) -> Result<Element, MjcfError> {
    parse(text, file, dir, 0)
}

fn parse(text: &str, file: &str, dir: &Path, depth: usize) -> Result<Element, MjcfError> {
    let doc = roxmltree::Document::parse(text).map_err(|e| MjcfError::Xml {
        file: file.to_string(),
        line: e.pos().row,
        message: e.to_string(),
    })?;
    let file: Arc<str> = Arc::from(file);
    let root = own(&doc, doc.root_element(), &file);
    if root.tag != "mujoco" {
        return Err(root.error("the root element of an MJCF model is <mujoco>"));
    }
    expand_includes(root, dir, depth)
}

fn own(doc: &roxmltree::Document, node: roxmltree::Node, file: &Arc<str>) -> Element {
    Element {
        tag: node.tag_name().name().to_string(),
        attrs: node.attributes().map(|a| (a.name().to_string(), a.value().to_string())).collect(),
        children: node.children().filter(|c| c.is_element()).map(|c| own(doc, c, file)).collect(),
        file: file.clone(),
        line: doc.text_pos_at(node.range().start).row,
    }
}

/// Replaces each `<include file>` below `e` by the top-level children of the included `<mujoco>`.
fn expand_includes(mut e: Element, dir: &Path, depth: usize) -> Result<Element, MjcfError> {
    let mut children = Vec::with_capacity(e.children.len());
    for child in std::mem::take(&mut e.children) {
        if child.tag != "include" {
            children.push(expand_includes(child, dir, depth)?);
            continue;
        }
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(child.error(format!("includes nest deeper than {MAX_INCLUDE_DEPTH} (an include cycle?)")));
        }
        let name = child.attr("file").ok_or_else(|| child.error("needs a file attribute"))?;
        let path: PathBuf = dir.join(name);
        let text = std::fs::read_to_string(&path)
            .map_err(|err| child.error(format!("cannot read {}: {err}", path.display())))?;
        let included = parse(&text, &path.display().to_string(), dir, depth + 1)?;
        children.extend(included.children);
    }
    e.children = children;
    Ok(e)
}
