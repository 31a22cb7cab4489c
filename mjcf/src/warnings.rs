//! What a model holds that kinloop cannot use, gathered while reading and reported in one warning, by name.

/// Unusable items and unknown elements, in the order met.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Warnings {
    /// Items kinloop has no term for (a tendon, a motor, a joint's frictionloss), each named.
    pub unusable: Vec<String>,
    /// Elements the reader does not know, with their lines.
    pub unknown: Vec<String>,
    /// Why a model whose hinges are all parallel was kept spatial (a ball joint, a slide along the hinges).
    pub kept_spatial: Option<String>,
}

impl Warnings {
    /// Records an item kinloop cannot use.
    pub fn unusable(&mut self, what: String) {
        self.unusable.push(what);
    }

    /// Records an element the reader does not know.
    pub fn unknown(&mut self, tag: &str, line: u32) {
        self.unknown.push(format!("<{tag}> at line {line}"));
    }

    /// True when there is nothing to report.
    pub fn is_empty(&self) -> bool {
        self.unusable.is_empty() && self.unknown.is_empty() && self.kept_spatial.is_none()
    }

    /// The one warning for `file`, or `None` when there is nothing to say.
    pub fn message(&self, file: &str) -> Option<String> {
        if self.is_empty() {
            return None;
        }
        let mut parts = Vec::new();
        if !self.unusable.is_empty() {
            parts.push(format!("not used (kinloop has no such term): {}", self.unusable.join("; ")));
        }
        if !self.unknown.is_empty() {
            parts.push(format!("unknown elements, skipped: {}", self.unknown.join(", ")));
        }
        if let Some(why) = &self.kept_spatial {
            parts.push(format!("its hinges are parallel, but it is kept spatial: {why}"));
        }
        Some(format!("{file}: {}", parts.join(". ")))
    }
}
