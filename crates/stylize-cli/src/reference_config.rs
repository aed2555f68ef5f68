//! Reading the reference implementation's JSON run configuration (`deform_by_csd`,
//! `cams_and_lights`, `guidance`; e.g. `example-run/confg-example-*.json` of the authors' code) into
//! a [`Config`].
//!
//! Mapped keys (under `deform_by_csd`):
//!
//! | reference | ours |
//! |---|---|
//! | `local_step_procrustes.lamb` | `darap.lambda` |
//! | `n_iters`, `lr` | `optim.iterations`, `optim.lr` |
//! | `n_accum_iters` (with `step_after_every_backward: true`) | `optim.steps_per_batch` |
//! | `view_batch_size`, `adapt_dists` | `camera.views`, `camera.adapt_distance` |
//! | `stage_I_weight`, `stage_II_weight_schedule` | `guidance.stage1_weight`, `guidance.stage2_weight` |
//! | `visual_loss_weight_schedule` (a constant) | `guidance.loss_scale` |
//! | `guidance.guidance_scale` | `guidance.scale` |
//! | `cams_and_lights.raster_res` | `render.width`, `render.height` |
//! | `cams_and_lights.{elev,dist}_minmax` | `camera.elevation_deg`, `camera.distance` |
//! | `cams_and_lights.azim_minmax` `[a, b]` | `camera.azimuth_deg = [a, b + 1]` (the reference draws from `uniform(a, b + 1)`) |
//! | `cams_and_lights.fov_minmax` `[f, f]` | `camera.fov_deg = 2·atan(1/⌊1/tan(f/2)⌋)`: the reference's integer-typed projection matrix truncates the focal length (60° → 90°, spec §6) |
//!
//! Settings we do not implement (a non-default value is an error, never silently ignored):
//! `optimize_deform_via` other than `verts_normals`, `solve_method` other than `arap`,
//! `arap_energy_type` other than `spokes_and_rims_mine`, `pin_first_vertex: false`,
//! `normalize_target_normals: false`, `optimizer_type` other than `Adam`,
//! `step_after_every_backward: false`, a non-zero `jacobian_id_loss_weight_schedule`, a background
//! other than white, `resize_for_guidance` other than `[224, 224, "cubic"]`, `light_power` ≠ 5,
//! `aug_loc: true`, `aug_light: false`, `look_at` ≠ origin, a fov range. Keys about files and
//! logging (`*_save_fname`, `view_once_every`, `save_at_epochs`, `dataset`, `up`) are reported as
//! ignored (`up` = `[0, −1, 0]` only mirrors the reference's images, spec §6).

use anyhow::{Context, bail};
use serde_json::Value;

use stylize::config::Config;

fn num(v: &Value, key: &str) -> anyhow::Result<Option<f64>> {
    match v.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(x) => x
            .as_f64()
            .map(Some)
            .with_context(|| format!("`{key}` must be a number, got {x}")),
    }
}

fn pair(v: &Value, key: &str) -> anyhow::Result<Option<[f64; 2]>> {
    match v.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::Array(a)) if a.len() == 2 => {
            let f = |x: &Value| {
                x.as_f64()
                    .with_context(|| format!("`{key}` must hold numbers"))
            };
            Ok(Some([f(&a[0])?, f(&a[1])?]))
        }
        Some(x) => bail!("`{key}` must be a pair [min, max], got {x}"),
    }
}

fn require(v: &Value, key: &str, expected: &Value) -> anyhow::Result<()> {
    match v.get(key) {
        None => Ok(()),
        Some(x) if x == expected => Ok(()),
        Some(x) => bail!("`{key}` = {x} is not supported (only {expected})"),
    }
}

/// The effective vertical field of view of the reference for its configured `fov` (degrees).
pub fn effective_fov_deg(fov_deg: f64) -> anyhow::Result<f64> {
    let focal = (1.0 / (fov_deg.to_radians() / 2.0).tan()).floor();
    if !(focal.is_finite() && focal >= 1.0) {
        bail!("fov {fov_deg}° truncates to a focal length of 0 in the reference (unusable)");
    }
    Ok(2.0 * (1.0 / focal).atan().to_degrees())
}

/// Parses a reference JSON configuration. Returns the configuration (our defaults for anything the
/// file does not set) and notes about keys that were ignored.
pub fn from_reference_json(text: &str) -> anyhow::Result<(Config, Vec<String>)> {
    // A leading byte-order mark (Windows editors) is not JSON.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let root: Value = serde_json::from_str(text).context("not valid JSON")?;
    let d = root
        .get("deform_by_csd")
        .context("no `deform_by_csd` object: not a reference configuration")?;
    let mut c = Config::default();
    let mut notes = Vec::new();
    for k in ["ps_recording_save_fname", "dataset"] {
        if root.get(k).is_some() {
            notes.push(format!(
                "ignored `{k}` (inputs and outputs come from the command line)"
            ));
        }
    }
    require(d, "optimize_deform_via", &"verts_normals".into())?;
    require(d, "solve_method", &"arap".into())?;
    require(d, "arap_energy_type", &"spokes_and_rims_mine".into())?;
    require(d, "pin_first_vertex", &true.into())?;
    require(d, "optimizer_type", &"Adam".into())?;
    require(d, "step_after_every_backward", &true.into())?;
    require(d, "mesh_batch_size", &1.into())?;
    if let Some(l) = d.get("local_step_procrustes") {
        require(l, "normalize_target_normals", &true.into())?;
        if let Some(lamb) = num(l, "lamb")? {
            c.darap.lambda = lamb;
        }
    }
    if let Some(n) = num(d, "n_iters")? {
        c.optim.iterations = n as u64;
    }
    if let Some(lr) = num(d, "lr")? {
        c.optim.lr = lr;
    }
    if let Some(n) = num(d, "n_accum_iters")? {
        c.optim.steps_per_batch = n as u32;
    }
    if let Some(n) = num(d, "view_batch_size")? {
        c.camera.views = n as usize;
    }
    if let Some(b) = d.get("adapt_dists") {
        c.camera.adapt_distance = b.as_bool().context("`adapt_dists` must be true or false")?;
    }
    if let Some(bg) = d.get("background_color")
        && bg != &serde_json::json!([1.0, 1.0, 1.0])
    {
        bail!("`background_color` = {bg} is not supported (only white)");
    }
    if let Some(r) = d.get("resize_for_guidance")
        && r != &serde_json::json!([224, 224, "cubic"])
    {
        bail!("`resize_for_guidance` = {r} is not supported (only [224, 224, \"cubic\"])");
    }
    if let Some(w) = num(d, "stage_I_weight")? {
        c.guidance.stage1_weight = w;
    }
    if let Some(s) = d.get("stage_II_weight_schedule") {
        c.guidance.stage2_weight = s
            .as_str()
            .context("`stage_II_weight_schedule` must be a string")?
            .to_string();
    }
    if let Some(s) = d.get("visual_loss_weight_schedule") {
        let s = s
            .as_str()
            .context("`visual_loss_weight_schedule` must be a string")?;
        let sched = optim::Schedule::parse(s)?;
        match sched.phases() {
            [
                optim::Phase::Constant {
                    value,
                    iterations: None,
                },
            ] => c.guidance.loss_scale = *value,
            _ => bail!("`visual_loss_weight_schedule` = {s:?}: only a constant is supported"),
        }
    }
    if let Some(s) = d.get("jacobian_id_loss_weight_schedule") {
        let s = s
            .as_str()
            .context("`jacobian_id_loss_weight_schedule` must be a string")?;
        let sched = optim::Schedule::parse(s)?;
        if sched.phases()
            != [optim::Phase::Constant {
                value: 0.0,
                iterations: None,
            }]
        {
            bail!("`jacobian_id_loss_weight_schedule` = {s:?} is not supported (only \"0.0\")");
        }
    }
    if let Some(g) = d.get("guidance")
        && let Some(s) = num(g, "guidance_scale")?
    {
        c.guidance.scale = s;
    }
    for k in [
        "optimized_quantity_save_fname",
        "view_once_every",
        "save_at_epochs",
    ] {
        if d.get(k).is_some() {
            notes.push(format!("ignored `deform_by_csd.{k}` (see run.* settings)"));
        }
    }
    if let Some(cl) = d.get("cams_and_lights") {
        if let Some(r) = num(cl, "raster_res")? {
            c.render.width = r as usize;
            c.render.height = r as usize;
        }
        if let Some(p) = pair(cl, "dist_minmax")? {
            c.camera.sampler.distance = p;
        }
        if let Some(p) = pair(cl, "elev_minmax")? {
            c.camera.sampler.elevation_deg = p;
        }
        if let Some(p) = pair(cl, "azim_minmax")? {
            c.camera.sampler.azimuth_deg = [p[0], p[1] + 1.0];
        }
        if let Some([lo, hi]) = pair(cl, "fov_minmax")? {
            if lo != hi {
                bail!("`fov_minmax` = [{lo}, {hi}]: a range of fields of view is not supported");
            }
            c.camera.sampler.fov_y_deg = effective_fov_deg(lo)?;
            notes.push(format!(
                "fov {lo}° is {:.2}° in effect (integer projection matrix, spec §6)",
                c.camera.sampler.fov_y_deg
            ));
        }
        if let Some(p) = num(cl, "light_power")?
            && p != 5.0
        {
            bail!("`light_power` = {p} is not supported (the renderer uses 5)");
        }
        require(cl, "aug_loc", &false.into())?;
        require(cl, "aug_light", &true.into())?;
        if let Some(l) = cl.get("look_at")
            && l != &serde_json::json!([0, 0, 0])
            && l != &serde_json::json!([0.0, 0.0, 0.0])
        {
            bail!("`look_at` = {l} is not supported (only the origin)");
        }
        if cl.get("up").is_some() {
            notes.push("ignored `cams_and_lights.up` (world up is +y; the reference's −y only mirrors its images)".into());
        }
    }
    c.validate()?;
    Ok((c, notes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The authors' example configuration (example-run/confg-example-cuteanimalthemedchair.json).
    const EXAMPLE: &str = r#"{
      "ps_recording_save_fname": "example-run/psrec.npz",
      "dataset": {"lists": {"fnames": ["chair.obj"], "prompts": ["a chair"], "prompts_negative": [null]}},
      "deform_by_csd": {
        "optimized_quantity_save_fname": "example-run/nrmls.npz",
        "optimize_deform_via": "verts_normals", "solve_method": "arap",
        "arap_energy_type": "spokes_and_rims_mine", "pin_first_vertex": true,
        "local_step_procrustes": {"lamb": 8.0, "normalize_target_normals": true},
        "n_iters": 2500, "lr": 0.0020, "optimizer_type": "Adam", "n_accum_iters": 2,
        "step_after_every_backward": true, "view_once_every": 100, "save_at_epochs": [],
        "mesh_batch_size": 1, "view_batch_size": 8, "adapt_dists": true,
        "background_color": [1.0, 1.0, 1.0], "resize_for_guidance": [224,224,"cubic"],
        "stage_I_weight": 1.0, "stage_II_weight_schedule": "0.0>0.2:1000; 0.2>0.3:750",
        "visual_loss_weight_schedule": "100.0", "jacobian_id_loss_weight_schedule": "0.0",
        "guidance": {"guidance_scale": 100.0},
        "cams_and_lights": {"raster_res": 512, "dist_minmax": [2.5,3.0], "azim_minmax": [0.0,360.0],
          "elev_minmax": [0.0,60.0], "fov_minmax": [60.0, 60.0], "light_power": 5.0,
          "aug_loc": false, "aug_light": true, "look_at": [0,0,0], "up": [0,-1,0]}
      }
    }"#;

    #[test]
    fn authors_example_config_maps_to_our_reference_defaults() {
        let (c, notes) = from_reference_json(EXAMPLE).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(c, Config::default());
        assert!(notes.iter().any(|n| n.contains("90.00°")), "{notes:?}");
    }

    #[test]
    fn effective_fov_follows_the_truncated_focal_length() {
        assert!((effective_fov_deg(60.0).unwrap_or(0.0) - 90.0).abs() < 1e-12);
        // 1/tan(20°) = 2.747 → 2 → 2·atan(1/2).
        let f = effective_fov_deg(40.0).unwrap_or(0.0);
        assert!((f - 2.0 * 0.5f64.atan().to_degrees()).abs() < 1e-12);
        assert!(effective_fov_deg(120.0).is_err());
    }

    #[test]
    fn unsupported_settings_are_errors_not_silently_dropped() {
        for (from, to) in [
            ("\"aug_light\": true", "\"aug_light\": false"),
            (
                "\"optimizer_type\": \"Adam\"",
                "\"optimizer_type\": \"SGD\"",
            ),
            (
                "\"jacobian_id_loss_weight_schedule\": \"0.0\"",
                "\"jacobian_id_loss_weight_schedule\": \"1.0\"",
            ),
            ("\"light_power\": 5.0", "\"light_power\": 3.0"),
        ] {
            let text = EXAMPLE.replacen(from, to, 1);
            assert_ne!(text, EXAMPLE, "{from}");
            assert!(from_reference_json(&text).is_err(), "{to} accepted");
        }
    }
}
