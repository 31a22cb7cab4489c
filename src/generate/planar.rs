//! The planar classes: four-bars across the Grashof classes, parallelograms, offset and inclined
//! slider-cranks, five-bars, Watt II and Stephenson III six-bars. Each is laid out by solving its loop's
//! geometry at a drawn input angle (closed at q0 by construction, see [`super::layout`]); a near-singular
//! draw picks the input within a small margin of a dead centre.

use kinloop_linkage::math::rng::TestRng;

use super::layout::{Hinge, LaidBody, LaidPin, Layout, P2};

/// Uniform in `[lo, hi)`.
pub fn uniform(rng: &mut TestRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * (rng.signed() + 1.0) * 0.5
}

/// Where two circles (centre, radius) meet, on the side `side` (±1) of the line between the centres;
/// `None` when they do not meet.
fn circles_meet(c1: P2, r1: f64, c2: P2, r2: f64, side: f64) -> Option<P2> {
    let d = [c2[0] - c1[0], c2[1] - c1[1]];
    let e = d[0].hypot(d[1]);
    if e <= 0.0 || e > r1 + r2 || e < (r1 - r2).abs() {
        return None;
    }
    let along = (r1 * r1 - r2 * r2 + e * e) / (2.0 * e);
    let h = (r1 * r1 - along * along).max(0.0).sqrt();
    let u = [d[0] / e, d[1] / e];
    Some([c1[0] + along * u[0] - side * h * u[1], c1[1] + along * u[1] + side * h * u[0]])
}

/// |sin| of the angle between `a` and `b`: zero when they are aligned (a dead centre).
fn alignment(a: P2, b: P2) -> f64 {
    let cross = a[0] * b[1] - a[1] * b[0];
    (cross / (a[0].hypot(a[1]) * b[0].hypot(b[1]))).abs()
}

fn diff(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

/// Whether a drawn configuration's distance from its dead centre suits the draw: a near-singular draw
/// wants it within (1e-3, 3e-2], a regular one beyond 0.15.
fn suits(margin: f64, near_singular: bool) -> bool {
    if near_singular {
        margin > 1e-3 && margin <= 3e-2
    } else {
        margin > 0.15
    }
}

/// A revolute body from `pivot` toward `toward` under `parent`, with `points` and mass `mass`.
fn body(name: &str, parent: Option<usize>, pivot: P2, toward: P2, points: Vec<P2>, mass: f64) -> LaidBody {
    LaidBody { name: name.into(), parent, pivot, toward, hinge: Hinge::Revolute, points, mass }
}

/// A four-bar with ground `d`, crank `a`, coupler `b`, rocker `c` (ground pivots at the origin and at
/// `(d, 0)`), at a crank angle drawn until the loop assembles and its transmission angle suits the draw.
/// `parallel` lays a parallelogram (a = c, b = d) in its parallel branch. `None` if no angle suits.
pub fn four_bar(
    rng: &mut TestRng,
    [d, a, b, c]: [f64; 4],
    masses: [f64; 3],
    near: bool,
    parallel: bool,
) -> Option<Layout> {
    let o4 = [d, 0.0];
    let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
    for _ in 0..4000 {
        let theta = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
        let pa = [a * theta.cos(), a * theta.sin()];
        let pb = if parallel { Some([pa[0] + d, pa[1]]) } else { circles_meet(pa, b, o4, c, side) };
        let Some(pb) = pb else { continue };
        // Dead centres: coupler and rocker aligned (the crank cannot drive), or crank and ground aligned
        // in a change-point linkage (the branches meet).
        let margin = alignment(diff(pb, pa), diff(pb, o4)).min(if parallel { alignment(pa, o4) } else { 1.0 });
        if !suits(margin, near) {
            continue;
        }
        let mut layout = Layout::default();
        layout.bodies.push(body("crank", None, [0.0, 0.0], pa, vec![], masses[0]));
        layout.bodies.push(body("coupler", Some(0), pa, pb, vec![], masses[1]));
        layout.bodies.push(body("rocker", None, o4, pb, vec![], masses[2]));
        layout.pins.push(LaidPin { body: 1, other: Some(2), at: pb });
        return Some(layout);
    }
    None
}

/// A slider-crank: crank `a` about the origin, coupler `b`, the slider on a line at angle `incline`
/// through `(0, offset)`; the crank angle drawn until the loop assembles and the crank's alignment with
/// the coupler suits the draw.
pub fn slider_crank(
    rng: &mut TestRng,
    a: f64,
    b: f64,
    offset: f64,
    incline: f64,
    masses: [f64; 3],
    near: bool,
) -> Option<Layout> {
    let dir = [incline.cos(), incline.sin()];
    let rail = [-offset * dir[1], offset * dir[0]];
    for _ in 0..4000 {
        let theta = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
        let pa = [a * theta.cos(), a * theta.sin()];
        // The slider at rail + t dir, |slider - pa| = b: t² + 2 t (r·dir) + |r|² - b² = 0 with r = rail - pa.
        let r = diff(rail, pa);
        let half = r[0] * dir[0] + r[1] * dir[1];
        let disc = half * half - (r[0] * r[0] + r[1] * r[1] - b * b);
        if disc < 0.0 {
            continue;
        }
        let t = -half + disc.sqrt();
        let slider = [rail[0] + t * dir[0], rail[1] + t * dir[1]];
        if !suits(alignment(pa, diff(slider, pa)), near) {
            continue;
        }
        let mut layout = Layout::default();
        layout.bodies.push(body("crank", None, [0.0, 0.0], pa, vec![], masses[0]));
        layout.bodies.push(LaidBody {
            name: "slider".into(),
            parent: None,
            pivot: slider,
            toward: [slider[0] + dir[0] * b * 0.2, slider[1] + dir[1] * b * 0.2],
            hinge: Hinge::Prismatic { rail },
            points: vec![],
            mass: masses[2],
        });
        layout.bodies.push(body("coupler", Some(1), slider, pa, vec![], masses[1]));
        layout.pins.push(LaidPin { body: 2, other: Some(0), at: pa });
        return Some(layout);
    }
    None
}

/// A five-bar: cranks `a1` about the origin and `a2` about `(g, 0)`, couplers `b1` and `b2` pinned where
/// they meet; both crank angles drawn until the loop assembles and the couplers' alignment suits the draw.
pub fn five_bar(rng: &mut TestRng, g: f64, [a1, a2, b1, b2]: [f64; 4], masses: [f64; 4], near: bool) -> Option<Layout> {
    let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
    for _ in 0..4000 {
        let t1 = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
        let t2 = uniform(rng, -std::f64::consts::PI, std::f64::consts::PI);
        let p1 = [a1 * t1.cos(), a1 * t1.sin()];
        let p2 = [g + a2 * t2.cos(), a2 * t2.sin()];
        let Some(pc) = circles_meet(p1, b1, p2, b2, side) else { continue };
        if !suits(alignment(diff(pc, p1), diff(pc, p2)), near) {
            continue;
        }
        let mut layout = Layout::default();
        layout.bodies.push(body("crank-1", None, [0.0, 0.0], p1, vec![], masses[0]));
        layout.bodies.push(body("crank-2", None, [g, 0.0], p2, vec![], masses[1]));
        layout.bodies.push(body("coupler-1", Some(0), p1, pc, vec![], masses[2]));
        layout.bodies.push(body("coupler-2", Some(1), p2, pc, vec![], masses[3]));
        layout.pins.push(LaidPin { body: 2, other: Some(3), at: pc });
        return Some(layout);
    }
    None
}

/// Which six-bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SixBar {
    /// Watt II: two four-bars in series sharing the ternary rocker.
    WattII,
    /// Stephenson III: a four-bar whose ternary coupler drives a dyad to a third ground pivot.
    StephensonIII,
}

/// A six-bar with joints at random points within `size` of the origin (each link at least a fifth of
/// `size` long): the loops are closed at q0 by construction, the mobility is one for generic points.
pub fn six_bar(rng: &mut TestRng, which: SixBar, size: f64, masses: [f64; 5]) -> Layout {
    let point = |rng: &mut TestRng| [size * uniform(rng, -1.0, 1.0), size * uniform(rng, -1.0, 1.0)];
    let far_enough = |pts: &[P2], p: P2| pts.iter().all(|q| diff(*q, p)[0].hypot(diff(*q, p)[1]) >= 0.2 * size);
    let mut pts: Vec<P2> = Vec::new();
    while pts.len() < 7 {
        let p = point(rng);
        if far_enough(&pts, p) {
            pts.push(p);
        }
    }
    let [o1, o2, o3, pa, pb, pc, pd] = [pts[0], pts[1], pts[2], pts[3], pts[4], pts[5], pts[6]];
    let mut layout = Layout::default();
    match which {
        SixBar::WattII => {
            layout.bodies.push(body("crank", None, o1, pa, vec![], masses[0]));
            layout.bodies.push(body("coupler-1", Some(0), pa, pb, vec![], masses[1]));
            layout.bodies.push(body("rocker", None, o2, pb, vec![pc], masses[2]));
            layout.bodies.push(body("coupler-2", Some(2), pc, pd, vec![], masses[3]));
            layout.bodies.push(body("output", None, o3, pd, vec![], masses[4]));
            layout.pins.push(LaidPin { body: 1, other: Some(2), at: pb });
        }
        SixBar::StephensonIII => {
            layout.bodies.push(body("crank", None, o1, pa, vec![], masses[0]));
            layout.bodies.push(body("coupler-1", Some(0), pa, pb, vec![pc], masses[1]));
            layout.bodies.push(body("rocker", None, o2, pb, vec![], masses[2]));
            layout.bodies.push(body("coupler-2", Some(1), pc, pd, vec![], masses[3]));
            layout.bodies.push(body("output", None, o3, pd, vec![], masses[4]));
            layout.pins.push(LaidPin { body: 1, other: Some(2), at: pb });
        }
    }
    layout.pins.push(LaidPin { body: 3, other: Some(4), at: pd });
    layout
}
