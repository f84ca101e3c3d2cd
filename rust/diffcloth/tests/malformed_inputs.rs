//! Issue 11 item 6: malformed files and placements surfaced as a panic (InternalError), a
//! stack overflow risk, "system matrix is not positive definite", or a silently dropped
//! vertex. Each is now an error of the right kind that names what is wrong.
use crate::common::*;
use diffcloth::{Error, SceneConfig, Simulator};

const NAPKIN_WITHOUT_MESH: &str = "h = 0.01\neffects = [\"gravity\", \"stretch\", \"bend\"]\n\
     [material]\ndensity = 0.2\nk_stretch = 200.0\nk_bend = 0.05\n";

fn obj_scene(name: &str, obj: &[u8]) -> Result<Simulator, Error> {
    let dir = std::env::temp_dir().join(format!("diffcloth_issue11_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, obj).unwrap();
    let toml = format!(
        "{NAPKIN_WITHOUT_MESH}[mesh]\nkind = \"obj\"\npath = {:?}\n",
        path.display().to_string()
    );
    Simulator::new(&SceneConfig::from_toml_str(&toml)?)
}

#[test]
fn malformed_toml_is_a_config_error() {
    let deep = format!("a = {}{}", "[".repeat(100_000), "]".repeat(100_000));
    let err = SceneConfig::from_toml_str(&deep).unwrap_err();
    assert!(matches!(err, Error::Config(_)), "{err}");
    let dir = std::env::temp_dir();
    let path = dir.join(format!("diffcloth_issue11_{}.toml", std::process::id()));
    std::fs::write(&path, b"name = \"\xff\xfe\"\n").unwrap();
    let err = SceneConfig::from_toml_file(&path).unwrap_err();
    std::fs::remove_file(&path).ok();
    assert!(err.to_string().contains("UTF-8"), "{err}");
    let bom = format!("\u{feff}{NAPKIN_WITHOUT_MESH}[mesh]\nkind = \"hat\"\n");
    assert!(SceneConfig::from_toml_str(&bom).is_ok());
    let deep_json = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    let err = SceneConfig::from_json_str(&deep_json, &dir).unwrap_err();
    assert!(matches!(err, Error::Config(_)), "{err}");
}

#[test]
fn a_placement_that_ruins_the_mesh_is_a_config_error_naming_it() {
    for (key, value) in [("scale", "1e150"), ("translate", "[1e300, 0, 0]")] {
        let mut cfg = load_config("napkin");
        match key {
            "scale" => cfg.placement.scale = 1e150,
            _ => cfg.placement.translate = [1e300, 0.0, 0.0],
        }
        let err = Simulator::new(&cfg).err().expect("refused");
        assert!(matches!(err, Error::Config(_)), "{key}: {err}");
        assert!(err.to_string().contains("placement"), "{err}");
        assert!(
            err.to_string().contains(&format!("{key} = ")),
            "{value}: {err}"
        );
    }
    // Shrunk onto its translation: rounded to degenerate triangles.
    let mut cfg = load_config("napkin");
    cfg.placement.scale = 1e-150;
    let err = Simulator::new(&cfg).err().expect("refused");
    assert!(err.to_string().contains("scale = 1e-150"), "{err}");
    // Shrunk at the origin: too small to factor; the message points at the scale.
    cfg.placement.translate = [0.0; 3];
    cfg.placement.scale = 1e-20;
    let err = Simulator::new(&cfg).err().expect("refused");
    assert!(matches!(err, Error::Solver(_)), "{err}");
    assert!(err.to_string().contains("placement.scale"), "{err}");
}

#[test]
fn obj_files_unused_vertices_are_named_and_a_bom_is_skipped() {
    let square = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
    let err = obj_scene("unused.obj", format!("{square}v 5 5 5\n").as_bytes())
        .err()
        .expect("refused");
    assert!(matches!(err, Error::Mesh(_)), "{err}");
    assert!(
        err.to_string()
            .contains("line 7: vertex 5 is used by no face"),
        "{err}"
    );
    let sim = obj_scene("bom.obj", format!("\u{feff}{square}").as_bytes()).unwrap();
    assert_eq!(sim.num_nodes(), 4);
}
