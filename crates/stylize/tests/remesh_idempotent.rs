//! `--remesh auto` leaves the remesher's own output alone (issue 40): for every fixture mesh, the
//! mesh a run would optimize after `--remesh on` (repaired, side-2 normalized, remeshed to 1.5 % of
//! the diagonal, normalized again), written to a file and read back as a new run's input, is not
//! remeshed again by `auto` — by the documented criterion (`stylize::remeshing::remeshing_advised`:
//! edge-length std/mean ≤ 0.4 and at most 1 % of the faces with a corner under 10°), which this
//! test does not restate. Costs about 3 s in the dev profile (six small meshes remeshed once).

use std::path::PathBuf;

use stylize::config::RegionSection;
use stylize::frame::UpAxis;
use stylize::remeshing::{RemeshSetting, remeshing_advised};
use stylize::runner::prepare_run_mesh;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/meshes")
        .join(name)
}

#[test]
fn auto_keeps_the_remeshers_output_of_every_fixture() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let region = RegionSection::default();
    for name in [
        "bunny.obj",
        "cow.off",
        "triceratops.off",
        "eight.off",
        "fandisk.off",
        "bone.ply",
    ] {
        let first = prepare_run_mesh(
            &fixture(name),
            RemeshSetting::On,
            UpAxis::default(),
            &region,
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let remeshed = first
            .remesh
            .remeshed
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: `on` remeshes"));
        let out = dir.path().join(format!("{name}.remeshed.obj"));
        mesh_core::io::write_mesh(&out, &first.mesh, None).unwrap_or_else(|e| panic!("{e}"));
        let second = prepare_run_mesh(&out, RemeshSetting::Auto, UpAxis::default(), &region)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            second.remesh.remeshed.is_none(),
            "{name}: auto remeshes the remesher's output again ({}); after the first remeshing: {}",
            second.remesh.reason,
            stylize::remeshing::quality_line(&remeshed.after)
        );
        // The same verdict from the criterion itself, on the figures of the first run's report.
        assert_eq!(
            remeshing_advised(&remeshed.after),
            None,
            "{name}: {}",
            stylize::remeshing::quality_line(&remeshed.after)
        );
        assert_eq!(second.mesh.faces, first.mesh.faces, "{name}: kept exactly");
    }
}
