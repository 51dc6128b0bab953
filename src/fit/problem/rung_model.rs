//! The model a parameter set describes: the rung built at its shapes, its albedos, and the
//! names and descriptions the reports use.

#[allow(unused_imports)]
use super::*;

/// Build the rung at the shape parameters of `set` with the given knobs.
pub fn model_for(
    set: &ParamSet,
    quadrature_order: usize,
    histogram_bins: usize,
    azimuth_nodes: usize,
    map: Option<Arc<TopologyMap>>,
) -> Box<dyn ShadingModel> {
    model::with_fuzz(
        model_under_fuzz(set, quadrature_order, histogram_bins, azimuth_nodes, map),
        set.shape_value(Param::FuzzDepth),
        set.shape_value(Param::FuzzAsymmetry),
    )
}

/// [`model_for`] without its fuzz layer (the layer is the outermost part: it applies to the
/// bases of this model pair by pair).
pub fn model_under_fuzz(
    set: &ParamSet,
    quadrature_order: usize,
    histogram_bins: usize,
    azimuth_nodes: usize,
    map: Option<Arc<TopologyMap>>,
) -> Box<dyn ShadingModel> {
    model::with_spread(
        model::with_fresnel(
            aligned_model_for(set, quadrature_order, histogram_bins, map),
            set.shape_value(Param::FresnelIor),
        ),
        set.shape_value(Param::AzimuthSpread),
        azimuth_nodes,
        set.shape_value(Param::Azimuth).to_radians(),
    )
}

fn aligned_model_for(
    set: &ParamSet,
    quadrature_order: usize,
    histogram_bins: usize,
    map: Option<Arc<TopologyMap>>,
) -> Box<dyn ShadingModel> {
    let topology = Topology {
        height: set.shape_value(Param::Height),
        map_scale: set.shape_value(Param::MapScale),
        map,
    };
    (set.rung.rung().build)(&model::AlignedInputs {
        exponent: set.shape_value(Param::Exponent),
        spacing: set.shape_value(Param::Spacing),
        alpha_x: set.shape_value(Param::AlphaX),
        alpha_y: set.shape_value(Param::AlphaY),
        quadrature_order,
        histogram_bins,
        topology: &topology,
        gltf: crate::model::params::GltfShape::of(|p| set.shape_value(p))
            .with_variant(set.gltf_variant),
        principled: crate::model::params::PrincipledShape::of(|p| set.shape_value(p)),
        openpbr: crate::model::params::OpenPbrShape::of(|p| set.shape_value(p)),
    })
}

/// The albedos of `set` as the model takes them (a tied substrate shares kd).
pub fn albedos_of(set: &ParamSet) -> model::Albedos {
    let mut a = model::Albedos::grey(0.0, 0.0, 0.0);
    a.rgb = set.channels == 3;
    for p in &set.albedos {
        match p.component {
            Component::Diffuse => {
                a.diffuse = p.value;
                if set.substrate_tied {
                    a.substrate = p.value;
                }
                if set.gltf_variant == crate::model::rungs::gltf::GltfVariant::Threejs {
                    // the threejs variant's c^2 column
                    a.substrate = p.value.map(|c| c * c);
                }
            }
            Component::Specular => a.specular = p.value,
            Component::Substrate => a.substrate = p.value,
            Component::Fuzz => a.fuzz = p.value,
        }
    }
    a
}

pub fn albedo_label(set: &ParamSet, i: usize, c: usize) -> String {
    if set.channels == 1 || set.albedos[i].grey {
        set.albedos[i].name.to_string()
    } else {
        format!("{}[{}]", set.albedos[i].name, ["r", "g", "b"][c])
    }
}

/// "name = value, ..." of a parameter set, for error messages.
pub fn describe(set: &ParamSet) -> String {
    let mut parts: Vec<String> = set
        .shapes
        .iter()
        .map(|s| format!("{} = {}", s.kind.name(), s.value))
        .collect();
    for a in &set.albedos {
        parts.push(format!("{} = {:?}", a.name, &a.value[..set.channels]));
    }
    parts.join(", ")
}
