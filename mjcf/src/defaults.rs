//! `<default>` classes: nested classes inherit their parent's attributes per element kind; an element takes
//! its own `class`, else the `childclass` of the nearest enclosing body, else the top-level class `main`.
//! Its own attributes override the class's.

use std::collections::HashMap;

use crate::error::MjcfError;
use crate::xml::Element;

/// The top-level default class's name.
pub const MAIN: &str = "main";

/// Attributes per element kind (`joint`, `geom`, ...) for each class.
#[derive(Clone, Debug, Default)]
pub struct Defaults {
    classes: HashMap<String, HashMap<String, Vec<(String, String)>>>,
}

impl Defaults {
    /// Reads every `<default>` directly under `<mujoco>` (and their nested classes).
    pub fn read(root: &Element) -> Result<Defaults, MjcfError> {
        let mut defaults = Defaults::default();
        defaults.classes.insert(MAIN.to_string(), HashMap::new());
        for d in root.children_named("default") {
            // The top-level <default> is `main` whatever its class attribute says.
            let name = d.attr("class").unwrap_or(MAIN).to_string();
            defaults.read_class(d, name, &HashMap::new())?;
        }
        Ok(defaults)
    }

    fn read_class(
        &mut self,
        d: &Element,
        name: String,
        inherited: &HashMap<String, Vec<(String, String)>>,
    ) -> Result<(), MjcfError> {
        let mut own = inherited.clone();
        for e in d.children.iter().filter(|c| c.tag != "default") {
            let attrs = own.entry(e.tag.clone()).or_default();
            for (k, v) in &e.attrs {
                match attrs.iter_mut().find(|(ak, _)| ak == k) {
                    Some(slot) => slot.1 = v.clone(),
                    None => attrs.push((k.clone(), v.clone())),
                }
            }
        }
        for child in d.children_named("default") {
            let child_name = child.attr("class").ok_or_else(|| child.error("a nested <default> needs a class"))?;
            if self.classes.contains_key(child_name) {
                return Err(child.error(format!("default class '{child_name}' is defined twice")));
            }
            self.read_class(child, child_name.to_string(), &own)?;
        }
        if name != MAIN && self.classes.contains_key(&name) {
            return Err(d.error(format!("default class '{name}' is defined twice")));
        }
        self.classes.insert(name, own);
        Ok(())
    }

    /// Checks that `class` exists, naming `at` when it does not.
    pub fn check_class(&self, class: &str, at: &Element) -> Result<(), MjcfError> {
        if self.classes.contains_key(class) {
            return Ok(());
        }
        let mut known: Vec<&str> = self.classes.keys().map(String::as_str).collect();
        known.sort_unstable();
        Err(at.error(format!("unknown default class '{class}' (known: {})", known.join(", "))))
    }

    /// `e` with the attributes of its class filled in; `childclass` is the enclosing body's active class.
    pub fn resolve(&self, e: &Element, childclass: &str) -> Result<Element, MjcfError> {
        let class = e.attr("class").unwrap_or(childclass);
        self.check_class(class, e)?;
        let mut out = e.clone();
        if let Some(attrs) = self.classes[class].get(&e.tag) {
            for (k, v) in attrs {
                if out.attr(k).is_none() {
                    out.attrs.push((k.clone(), v.clone()));
                }
            }
        }
        Ok(out)
    }
}
