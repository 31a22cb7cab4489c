//! An MJCF model → a kinloop [`Scene`]: `<compiler>`, `<default>`, `<option gravity>`, `<worldbody>`,
//! `<equality>` and `<actuator>`, checked by compiling the scene before it is handed out, so a
//! half-imported scene is never used; a model that moves in one plane becomes a planar scene ([`crate::planar`]).

use std::path::Path;

use kinloop_linkage::math::space::{SceneKind, Spatial};
use kinloop_linkage::model::scene::Scene;
use kinloop_linkage::Model;

use crate::actuator::read_actuator;
use crate::defaults::{Defaults, MAIN};
use crate::equality::read_equality;
use crate::error::MjcfError;
use crate::frames::Compiler;
use crate::planar::{reduce, Reduction};
use crate::tree::{finish_bodies, read_tree};
use crate::warnings::Warnings;
use crate::xml::{self, Element};

/// MuJoCo's default gravity, m/s².
const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// Top-level elements that hold nothing for the mechanics (drawing, assets, sizes, sensors, contacts).
const IGNORED: &[&str] =
    &["visual", "asset", "statistic", "size", "custom", "extension", "keyframe", "sensor", "contact"];

/// An imported model: the scene and what the model held that the scene does not.
#[derive(Clone, Debug, PartialEq)]
pub struct Import {
    /// The scene (it compiles).
    pub scene: Scene,
    /// The unusable items and unknown elements.
    pub warnings: Warnings,
    /// Whether the model was reduced to a planar scene, and what was dropped (or why it was not).
    pub reduction: Reduction,
}

/// Reads the model file at `path` (and its includes).
pub fn import_file(path: &Path) -> Result<Import, MjcfError> {
    let root = xml::read_file(path)?;
    import_tree(&root)
}

/// Reads model text; `file` names it in messages and `dir` is where its includes are found.
pub fn import_str(text: &str, file: &str, dir: &Path) -> Result<Import, MjcfError> {
    let root = xml::read_str(text, file, dir)?;
    import_tree(&root)
}

fn import_tree(root: &Element) -> Result<Import, MjcfError> {
    let compiler = Compiler::read(root)?;
    let defaults = Defaults::read(root)?;
    let mut warnings = Warnings::default();
    let mut gravity = GRAVITY.to_vec();
    for c in &root.children {
        match c.tag.as_str() {
            "option" => {
                if let Some(g) = c.fixed::<3>("gravity")? {
                    gravity = g.to_vec();
                }
            }
            "tendon" => c.children.iter().for_each(|t| warnings.unusable(format!("<{}> tendon '{}'", t.tag, label(t)))),
            "deformable" => c.children.iter().for_each(|t| warnings.unusable(format!("<{}> '{}'", t.tag, label(t)))),
            "compiler" | "default" | "worldbody" | "equality" | "actuator" => {}
            t if IGNORED.contains(&t) => {}
            other => warnings.unknown(other, c.line),
        }
    }
    let world = root.children_named("worldbody").next().ok_or_else(|| root.error("a model needs a <worldbody>"))?;
    let mut tree = read_tree(world, &compiler, &defaults, &mut warnings)?;
    finish_bodies(&mut tree)?;
    let mut cuts = Vec::new();
    for e in root.children_named("equality").flat_map(|q| q.children.iter()) {
        if let Some(cut) = read_equality(&defaults.resolve(e, MAIN)?, &tree, &mut warnings)? {
            cuts.push(cut);
        }
    }
    for e in root.children_named("actuator").flat_map(|q| q.children.iter()) {
        read_actuator(&defaults.resolve(e, MAIN)?, &tree.joint_index, &mut tree.joints, &mut warnings)?;
    }
    let file = root.file.to_string();
    let scene = Scene {
        name: root.attr("model").unwrap_or("").to_string(),
        kind: SceneKind::Spatial,
        gravity,
        length_scale: None,
        baumgarte: Default::default(),
        contact: Default::default(),
        closure_tolerance: None,
        bodies: tree.bodies,
        joints: tree.joints,
        cuts,
        ops: tree.ops,
        obstacles: Vec::new(),
    };
    let model = Model::<Spatial>::compile(&scene, &file)
        .map_err(|e| MjcfError::Scene { file: file.clone(), message: e.to_string() })?;
    let (scene, reduction) = reduce(scene, &model, &file);
    if let Reduction::Spatial { why, near_planar: true } = &reduction {
        warnings.kept_spatial = Some(why.clone());
    }
    Ok(Import { scene, warnings, reduction })
}

fn label(e: &Element) -> String {
    e.attr("name").map_or_else(|| format!("@{}", e.line), str::to_string)
}
