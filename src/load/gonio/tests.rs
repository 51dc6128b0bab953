use super::*;

fn parse(text: &str) -> Result<Samples> {
    read(text.as_bytes(), "g.csv", &GonioOptions::default())
}

#[test]
fn byte_order_mark_blank_lines_and_indented_comments_are_not_data() {
    let s = parse(
        "\u{feff}\n  \n  # exported by a spreadsheet\ntheta_i,phi_i,theta_o,phi_o,brdf\n  # indented\n30,0,30,180,0.2\n\n   \n40,10,20,90,0.3\n",
    )
    .unwrap();
    assert_eq!(s.samples.len(), 2);
    assert_eq!(s.samples[0].origin, Origin::Line(6));
    assert_eq!(s.samples[1].origin, Origin::Line(9));
    // and an error after them still names the right line
    let e = parse("\n# c\ntheta_i,phi_i,theta_o,phi_o,brdf\n30,0,30,x,0.2\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("g.csv:4") && e.contains("phi_o"), "{e}");
}

#[test]
fn brdf_and_radiance_forms_agree() {
    let a = parse("theta_i,phi_i,theta_o,phi_o,brdf\n60,0,10,90,0.2\n").unwrap();
    // radiance = f E cos(theta_i) = 0.2 * 3 * 0.5
    let b = parse("theta_i,phi_i,theta_o,phi_o,radiance,irradiance\n60,0,10,90,0.3,3\n").unwrap();
    assert!((a.samples[0].value[0] - b.samples[0].value[0]).abs() < 1e-15);
    assert_eq!(a.channels, 1);
}

#[test]
fn rgb_with_sigma() {
    let s = parse("theta_i,phi_i,theta_o,phi_o,brdf_r,brdf_g,brdf_b,sigma_r,sigma_g,sigma_b\n10,0,20,0,0.1,0.2,0.3,0.01,0.01,0.02\n").unwrap();
    assert_eq!(s.channels, 3);
    assert_eq!(s.samples[0].value, [0.1, 0.2, 0.3]);
    assert_eq!(s.samples[0].sigma, Some([0.01, 0.01, 0.02]));
}

#[test]
fn radians_are_caught() {
    let mut text = String::from("theta_i,phi_i,theta_o,phi_o,brdf\n");
    for i in 0..20 {
        text += &format!(
            "{},{},{},{},0.1\n",
            0.05 * i as f64,
            0.3 * i as f64,
            1.2,
            3.0
        );
    }
    let e = parse(&text).unwrap_err().to_string();
    assert!(e.contains("look like radians"), "{e}");
    assert!(read(
        text.as_bytes(),
        "g.csv",
        &GonioOptions {
            small_angles_ok: true,
            ..Default::default()
        }
    )
    .is_ok());
}

#[test]
fn skipping_counts_bad_rows() {
    let text = "theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.1\n10,0,95,0,0.1\n10,x,10,0,0.1\n10,0,10\n20,0,10,0,0.2\n";
    let e = parse(text).unwrap_err().to_string();
    assert!(e.contains("g.csv:3") && e.contains("horizon"), "{e}");
    let s = read(
        text.as_bytes(),
        "g.csv",
        &GonioOptions {
            skip_bad_rows: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(s.samples.len(), 2);
    assert_eq!(s.dropped.skipped_rows, 3);
}

#[test]
fn negative_beyond_noise() {
    let e = parse("theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.5\n10,0,20,0,-0.2\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("g.csv:3") && e.contains("negative beyond noise"),
        "{e}"
    );
    assert!(parse("theta_i,phi_i,theta_o,phi_o,brdf\n10,0,10,0,0.5\n10,0,20,0,-0.001\n").is_ok());
    let e =
        parse("theta_i,phi_i,theta_o,phi_o,brdf,sigma\n10,0,10,0,0.5,0.01\n10,0,20,0,-0.1,0.01\n")
            .unwrap_err()
            .to_string();
    assert!(e.contains("sigma"), "{e}");
}

#[test]
fn delimiters_are_sniffed_and_columns_mapped() {
    let comma =
        parse("theta_i,phi_i,theta_o,phi_o,brdf\n30,0,30,180,0.2\n40,10,20,90,0.3\n").unwrap();
    for (text, d) in [
        ("theta_i\tphi_i\ttheta_o\tphi_o\tbrdf\n30\t0\t30\t180\t0.2\n40\t10\t20\t90\t0.3\n", Delimiter::Tab),
        ("theta_i;phi_i;theta_o;phi_o;brdf\n30;0;30;180;0.2\n40;10;20;90;0.3\n", Delimiter::Semicolon),
        ("# c\ntheta_i  phi_i theta_o phi_o brdf\n  30 0\t  30 180 0.2\n# x y\n40 10 20 90 0.3  \n", Delimiter::Whitespace),
    ] {
        let (s, f) = read_with_format(text.as_bytes(), "g.csv", &GonioOptions::default())
            .unwrap();
        assert_eq!(f.delimiter, d, "{text}");
        assert_eq!(s.samples.len(), 2);
        for (a, b) in s.samples.iter().zip(&comma.samples) {
            assert_eq!((a.l, a.v, a.value), (b.l, b.v, b.value));
        }
    }
    let opts = GonioOptions {
        columns: parse_columns("theta_i=ti, phi_i=pi,theta_o=to,phi_o=po,brdf=f").unwrap(),
        ..Default::default()
    };
    check_columns(&opts.columns).unwrap();
    let (s, f) = read_with_format(
        "ti,pi,to,po,f\n30,0,30,180,0.2\n".as_bytes(),
        "g.csv",
        &opts,
    )
    .unwrap();
    assert_eq!(s.samples[0].value, comma.samples[0].value);
    assert!(f.describe().contains("ti -> theta_i"), "{}", f.describe());
    let e = parse("theta_in,phi_in,theta_out,phi_out,f\n30,0,30,180,0.2\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown column `theta_in`")
            && e.contains("`phi_out`")
            && e.contains("theta_i, phi_i"),
        "{e}"
    );
    assert!(check_columns(&parse_columns("theta=x").unwrap()).is_err());
    assert!(parse_columns("theta_i").is_err());
}

#[test]
fn radians_are_converted_when_said() {
    let deg = "theta_i,phi_i,theta_o,phi_o,brdf\n30,90,60,180,0.1\n";
    let rad = format!(
        "theta_i,phi_i,theta_o,phi_o,brdf\n{},{},{},{},0.1\n",
        30f64.to_radians(),
        90f64.to_radians(),
        60f64.to_radians(),
        180f64.to_radians()
    );
    let opts = GonioOptions {
        angles: AngleUnit::Rad,
        ..Default::default()
    };
    let a = read(rad.as_bytes(), "g.csv", &opts).unwrap();
    let b = parse(deg).unwrap();
    assert!((a.samples[0].l - b.samples[0].l).norm() < 1e-12);
    assert!((a.samples[0].v - b.samples[0].v).norm() < 1e-12);
    // a theta beyond the horizon is named as the file gives it, and in degrees
    let e = read(
        "theta_i,phi_i,theta_o,phi_o,brdf\n1.6,0,0.2,0,0.1\n".as_bytes(),
        "g.csv",
        &opts,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("g.csv:2") && e.contains("1.6 rad (91.673 degrees)"), "{e}");
    assert_eq!("RAD".parse::<AngleUnit>(), Ok(AngleUnit::Rad));
    assert!("grad".parse::<AngleUnit>().unwrap_err().contains("deg"));
}
