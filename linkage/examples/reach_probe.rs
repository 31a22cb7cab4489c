use kinloop_linkage::algorithms::reach::{survey_op, SurveyConfig};
use kinloop_linkage::{
    math::space::Planar, math::space::SceneKind, math::space::Space, math::space::Spatial, math::space::VecOps,
    model::builtin, model::Model,
};
fn run<S: Space>(scene: &kinloop_linkage::model::scene::Scene) {
    let model: Model<S> = Model::compile(scene, &scene.name).unwrap();
    for op in 0..model.ops.len() {
        let t = std::time::Instant::now();
        let r = survey_op(&model, op, &SurveyConfig::default()).unwrap();
        println!("{:22} {:10} dof {} samples {:4} extent {:?} rot {:.2} tour {:2} static {:.3} N (max {:.2}) {:.4} Nm  1/m_max {:.3} 1/I_max {:.1}  L {:.3}  {:.1} ms",
            scene.name, model.ops[op].name, r.dof, r.samples, r.extent().as_slice().iter().map(|x| (x*1000.0).round()/1000.0).collect::<Vec<_>>(), r.rotation_range, r.tour.len(),
            r.static_force_n, r.static_force_max_n, r.static_torque_nm, r.inverse_mass_max, r.inverse_rotational_inertia_max, model.length_scale, t.elapsed().as_secs_f64()*1e3);
    }
}
fn main() {
    for (name, _) in builtin::SCENE_FILES {
        let scene = builtin::scene(name).unwrap().unwrap();
        match scene.kind {
            SceneKind::Planar => run::<Planar>(&scene),
            SceneKind::Spatial => run::<Spatial>(&scene),
        }
    }
}
