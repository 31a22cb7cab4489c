//! `<equality>`: a `connect` is a spherical cut (the anchor in body1's frame; body2's point is where the
//! anchor lies at qpos0, as MuJoCo computes it, unless given by `site2`), a `weld` a weld cut closed at
//! qpos0. Other equalities (joint, tendon, flex) are listed as unusable.

use kinloop_linkage::model::scene::{CutKindSpec, CutSpec, GROUND};
use nalgebra::Vector3;

use crate::error::MjcfError;
use crate::tree::{Carrier, Tree};
use crate::warnings::Warnings;
use crate::xml::Element;

/// One scene cut per usable `<connect>` and `<weld>` (`e` resolved against its defaults).
pub fn read_equality(e: &Element, tree: &Tree, warnings: &mut Warnings) -> Result<Option<CutSpec>, MjcfError> {
    let name = e.attr("name").map_or_else(|| format!("{}@{}", e.tag, e.line), str::to_string);
    if !matches!(e.tag.as_str(), "connect" | "weld") {
        warnings.unusable(format!("<{}> equality '{name}'", e.tag));
        return Ok(None);
    }
    if e.attr("active") == Some("false") {
        warnings.unusable(format!("inactive <{}> '{name}'", e.tag));
        return Ok(None);
    }
    let kind = if e.tag == "connect" { CutKindSpec::Spherical } else { CutKindSpec::Weld };
    let (a, point_a, b, point_b) = match (e.attr("site1"), e.attr("site2")) {
        (Some(s1), Some(s2)) => {
            let (a, pa) = site(e, tree, s1)?;
            let (b, pb) = site(e, tree, s2)?;
            (a, pa, b, Some(pb.as_slice().to_vec()))
        }
        (None, None) => {
            let body1 = e.attr("body1").ok_or_else(|| e.error("needs body1 (or site1 and site2)"))?;
            let c1 = carrier(e, tree, body1)?;
            let c2 = carrier(e, tree, e.attr("body2").unwrap_or("world"))?;
            let anchor = e.fixed::<3>("anchor")?.map_or_else(Vector3::zeros, Vector3::from);
            if kind == CutKindSpec::Spherical && e.attr("anchor").is_none() {
                return Err(e.error("a connect needs an anchor (in body1's frame)"));
            }
            (c1.body, c1.pose.point(&anchor), c2.body, None)
        }
        _ => return Err(e.error("give both site1 and site2, or body1 (and body2)")),
    };
    if kind == CutKindSpec::Weld {
        if let Some(rel) = e.numbers("relpose")? {
            if rel.len() == 7 && rel[3..].iter().any(|&x| x != 0.0) {
                warnings.unusable(format!("relpose of weld '{name}' (welded where it stands at qpos0)"));
            }
        }
    }
    if a == b {
        return Err(e.error("its two sides are on the same rigid body"));
    }
    let body_name = |i: Option<usize>| i.map_or_else(|| GROUND.to_string(), |i| tree.bodies[i].name.clone());
    Ok(Some(CutSpec {
        point_b,
        ..CutSpec::between(name, kind, body_name(a), point_a.as_slice().to_vec(), body_name(b))
    }))
}

fn carrier(e: &Element, tree: &Tree, body: &str) -> Result<Carrier, MjcfError> {
    tree.carriers.get(body).copied().ok_or_else(|| e.error(format!("no body named '{body}'")))
}

fn site(e: &Element, tree: &Tree, name: &str) -> Result<(Option<usize>, Vector3<f64>), MjcfError> {
    tree.sites.get(name).copied().ok_or_else(|| e.error(format!("no site named '{name}'")))
}
