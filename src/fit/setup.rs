//! The first stage: the parameter template from the config and what the data say about it.
//!
//! - When every sample carries its fibre direction (captures with a tangent map or a known
//!   azimuth), `fibre_azimuth_deg` is held fixed at the data's axial mean.
//! - Grey data stored as RGB (R = G = B, and equal sigmas, in every sample) is fitted as one
//!   channel: three copies of one number are one measurement, not three.

use super::config::FitConfig;
use super::parameters::{Param, ParamSet};
use crate::load::samples::Samples;
use crate::model::topology::TopologyMap;
use anyhow::{Context, Result};
use std::sync::Arc;

pub struct Setup {
    pub template: ParamSet,
    /// Channels fitted.
    pub channels: usize,
    pub map: Option<Arc<TopologyMap>>,
    /// What setup decided, for the report's warnings.
    pub notes: Vec<String>,
}

/// True when RGB data hold one grey value per sample (and one sigma).
pub fn grey_stored_as_rgb(samples: &Samples) -> bool {
    samples.channels == 3
        && samples.samples.iter().all(|s| {
            s.value[1] == s.value[0]
                && s.value[2] == s.value[0]
                && s.sigma.is_none_or(|g| g[1] == g[0] && g[2] == g[0])
        })
}

pub fn setup(samples: &Samples, cfg: &FitConfig) -> Result<Setup> {
    let mut notes = Vec::new();
    let channels = if grey_stored_as_rgb(samples) {
        notes.push(
            "the data are grey stored as RGB (R = G = B in every sample): fitted as one channel, \
             so each sample counts once"
                .to_string(),
        );
        1
    } else {
        samples.channels
    };
    let mut template = ParamSet::from_config(cfg, channels)?;
    if samples.samples.iter().all(|s| s.fibre_azimuth.is_some()) {
        if let Some(s) = template
            .shapes
            .iter_mut()
            .find(|s| s.kind == Param::Azimuth && s.vary)
        {
            s.vary = false;
            // the data's direction: axial mean (angles doubled, period 180 degrees)
            let (sn, cs) = samples
                .samples
                .iter()
                .filter_map(|x| x.fibre_azimuth)
                .fold((0.0, 0.0), |(a, b), psi| {
                    (a + (2.0 * psi).sin(), b + (2.0 * psi).cos())
                });
            let mean = 0.5 * sn.atan2(cs).to_degrees();
            let uniform = samples
                .samples
                .iter()
                .all(|x| x.fibre_azimuth == samples.samples[0].fibre_azimuth);
            s.value = mean.clamp(s.min, s.max);
            s.init = s.value;
            notes.push(if uniform {
                format!("`fibre_azimuth_deg` held at {mean:.4}: the data give the fibre direction")
            } else {
                format!("`fibre_azimuth_deg` held fixed: the data give the fibre direction per pixel (tangent map); {mean:.4} is their axial mean")
            });
        }
    }
    let map = match &cfg.knobs.topology_map {
        Some(_) if !cfg.components.topology_map => {
            notes.push("components.topology_map = false: the topology map is ignored".into());
            None
        }
        Some(p) => Some(Arc::new(
            TopologyMap::load(p).context("knobs.topology_map")?,
        )),
        None => None,
    };
    Ok(Setup {
        template,
        channels,
        map,
        notes,
    })
}
