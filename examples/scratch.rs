use fibrefit::model::*;
use fibrefit::model::topology::Topology;
fn main() {
    let th = 30f64.to_radians();
    let l = frame::direction_from_angles(th, 90f64.to_radians());
    let fr = FibreFrame::from_azimuth(0.0);
    let pairs = [DirectionPair::new(&fr, &Vec3::new(0.,0.,1.), &Vec3::new(0.,0.,1.)), DirectionPair::new(&fr, &l, &l)];
    for (i,pair) in pairs.iter().enumerate() {
        for phi in [0.0f64, 30.0, 60.0] {
            let h = 2.0*phi.to_radians().sin();
            let vt = varying_topology::VaryingTopology::new(2.0, 10.0, 16, vec![(h,1.0)]);
            let rf = reference::Reference::new(2.0, 10.0, Topology{height:h, map_scale:0.0, map:None});
            let b = vt.basis(pair); let r = rf.basis(pair);
            println!("pair {i} phi {phi}: vt d={:.10} sub={:.6} spec={:.6} | ref d={:.10} spec={:.6}", b.diffuse, b.substrate, b.specular, r.diffuse, r.specular);
        }
    }
}
