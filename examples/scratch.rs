use fibrefit::model::*;
fn main() {
    let fr = FibreFrame::from_azimuth(0.0);
    for (ax, ay) in [(0.05,0.1),(0.3,0.3),(1.0,1.0),(0.1,1.0)] {
        let w = ward::Ward::new(ax, ay);
        for thl in [0.0f64, 60.0, 85.0, 89.5] {
            let l = frame::direction_from_angles(thl.to_radians(), 0.4);
            let (nt, np) = (2000, 1000);
            let mut sum = 0.0;
            for i in 0..nt { let th = (i as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
                for j in 0..np { let ph = 2.0*std::f64::consts::PI*(j as f64+0.5)/np as f64;
                    let v = frame::direction_from_angles(th, ph);
                    sum += w.basis(&DirectionPair::new(&fr, &l, &v)).specular * th.cos() * th.sin(); } }
            sum *= (std::f64::consts::FRAC_PI_2 / nt as f64) * (2.0*std::f64::consts::PI/np as f64);
            println!("ward ax {ax} ay {ay} theta_l {thl}: specular albedo {sum:.4}");
        }
    }
}
