//! The `[world]` table's parsing: errors with lines and keys, the example configs, the
//! documented keys.

use super::*;
use std::path::Path;

fn world(text: &str) -> Result<WorldConfig, WorldConfigError> {
    let full = format!("[[agent]]\nid = 0\n[world]\n{text}");
    let c = Config::from_toml_str(&full, Path::new("w.toml")).unwrap();
    WorldConfig::from_config_text(&c, Some(full))
}

/// The line an error names (the `[world]` header is line 3 of [`world`]'s text).
fn error_line(text: &str) -> usize {
    match world(text).unwrap_err() {
        WorldConfigError::Invalid { line, .. } => line,
    }
}

#[test]
fn errors_carry_the_line_of_the_key() {
    assert_eq!(error_line("room_width = 1.0\nroom_depth = -3.0\n"), 5);
    assert_eq!(error_line("room_width = \"wide\"\n"), 4);
    // An unknown key: its own line.
    assert_eq!(error_line("room_width = 9.0\n\nbogus = 1\n"), 6);
    let objects = "[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\n\
                   size = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n\
                   [[world.object]]\nid = 2\nshape = \"sphere\"\nposition = [0.0, 0.5, 0.0]\n\
                   radius = 0.5\ncolour = [1, 2, 3]\n";
    assert_eq!(error_line(objects), 15);
    let range = "[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\n\
                 size = [1.0, 1.0, 1.0]\ncolor = [1, 2, 300]\n";
    assert_eq!(error_line(range), 9);
    let msg = world("room_width = -3.0\n").unwrap_err().to_string();
    assert!(
        msg.starts_with("w.toml:4: invalid `world.room_width`"),
        "{msg}"
    );
}

fn expect_key(text: &str, key: &str) {
    let e = world(text).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("`{key}`")),
        "expected key {key} in: {msg}"
    );
    assert!(msg.contains("w.toml"), "{msg}");
}

#[test]
fn the_example_configs_parse() {
    let c = Config::embedded_default().unwrap();
    let w = WorldConfig::from_config(&c).unwrap();
    assert!(w.objects.iter().any(|o| o.color == [220, 30, 30]));
    assert_eq!(w.agents.len(), 2);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/large-room.toml");
    let c = Config::load(path).unwrap();
    let w = WorldConfig::from_config(&c).unwrap();
    assert_eq!(c.agents.len(), 4);
    assert!(w.room_width > 10.0);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/vector-16.toml");
    let c = Config::load(path).unwrap();
    WorldConfig::from_config(&c).unwrap();
    assert_eq!(c.agents.len(), 16);
    assert!(c.agents.iter().all(|a| {
        let [cam] = &a.cameras[..] else { return false };
        (cam.width_px, cam.height_px) == (84, 84)
    }));
}

/// The keys a table accepts, from serde's "unknown field" message.
fn accepted_keys(table: &str) -> Vec<String> {
    let e = world(&format!("{table}zz_not_a_key = 1\n"))
        .unwrap_err()
        .to_string();
    let list = e
        .split("expected one of")
        .nth(1)
        .unwrap_or_else(|| panic!("{e}"));
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

#[test]
fn default_toml_documents_every_world_key() {
    let doc = vrsync_bridge::DEFAULT_CONFIG_TOML;
    let mut n = 0;
    for table in [
        "",
        "[[world.object]]\n",
        "[[world.agent]]\n",
        "[[world.goal]]\n",
    ] {
        for key in accepted_keys(table) {
            let documented = doc.lines().any(|l| {
                let l = l.trim_start_matches(['#', ' ']);
                l.starts_with(&format!("{key} ")) || l.starts_with(&format!("{key}="))
            }) || doc.contains(&format!("[[world.{key}]]"));
            assert!(
                documented,
                "`{key}` of {table:?} is not documented in default.toml"
            );
            n += 1;
        }
    }
    assert!(n > 25, "only {n} keys found");
}

#[test]
fn errors_name_the_key() {
    expect_key("bogus = 1\n", "world");
    expect_key("room_width = -3.0\n", "world.room_width");
    expect_key("room_width = \"wide\"\n", "world.room_width");
    expect_key(
        "[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 3]\n\
         [[world.object]]\nid = 2\nshape = \"sphere\"\nposition = [0.0, 0.5, 0.0]\nradius = 0.5\ncolour = [1, 2, 3]\n",
        "world.object[1]",
    );
    expect_key(
        "[[world.object]]\nid = 1\nshape = \"box\"\nposition = [0.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\ncolor = [1, 2, 300]\n",
        "world.object[0].color",
    );
    expect_key(
        "[[world.object]]\nid = 1\nshape = \"sphere\"\nposition = [40.0, 0.5, 0.0]\nradius = 0.5\ncolor = [1, 2, 3]\n",
        "world.object[0].position",
    );
    expect_key(
        "[[world.object]]\nid = 1\nshape = \"cone\"\nposition = [0.0, 0.5, 0.0]\nradius = 0.5\ncolor = [1, 2, 3]\n",
        "world.object[0].shape",
    );
    expect_key(
        "[[world.goal]]\nobject = 5\naction = \"grasp\"\nreward = 1.0\n",
        "world.goal[0].object",
    );
    expect_key("[[world.goal]]\nreward = 1.0\n", "world.goal[0]");
    expect_key("eye_height = 5.0\n", "world.eye_height");
}
