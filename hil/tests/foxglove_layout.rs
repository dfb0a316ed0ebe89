//! `docs/foxglove-layout.json`, the layout shipped for Foxglove (and Lichtblick), is one that the
//! app can open and that shows our data: the app cannot be installed here, so this checks what
//! the app needs of a layout file. Its structure: `configById` with a config per panel, named
//! `<panel type>!<id>` after built-in panels, and a `layout` tree (`direction`, `first`,
//! `second`, `splitPercentage`) whose leaves are exactly those panels. Its topics: every topic a
//! panel names (paths in Foxglove's message path syntax) is a channel of the live view or of
//! the recordings, so one layout serves both.

use serde_json::Value;
use std::collections::BTreeSet;

fn layout() -> Value {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/foxglove-layout.json");
    serde_json::from_str(&std::fs::read_to_string(p).expect("docs/foxglove-layout.json"))
        .expect("the layout is JSON")
}

fn leaves(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::String(s) => out.push(s.clone()),
        Value::Object(o) => {
            assert!(
                matches!(
                    o.get("direction").and_then(Value::as_str),
                    Some("row" | "column")
                ),
                "a split has a direction: {v}"
            );
            let pct = o.get("splitPercentage").and_then(Value::as_f64);
            assert!(pct.is_some_and(|p| p > 0.0 && p < 100.0), "{v}");
            leaves(&o["first"], out);
            leaves(&o["second"], out);
        }
        _ => panic!("not a panel or a split: {v}"),
    }
}

/// The topic a message path starts with: `/nav/event{kind=="x"}.progress.heading_deg` ->
/// `/nav/event`.
fn topic_of(path: &str) -> &str {
    let end = path.find(['{', '.', '[']).unwrap_or(path.len());
    &path[..end]
}

fn topics_named(id: &str, cfg: &Value) -> Vec<String> {
    let mut t = Vec::new();
    let mut add = |s: Option<&str>| {
        if let Some(s) = s.filter(|s| !s.is_empty()) {
            t.push(topic_of(s).to_string());
        }
    };
    add(cfg["followTopic"].as_str());
    add(cfg["topicToRender"].as_str());
    add(cfg["topicPath"].as_str());
    for p in cfg["paths"].as_array().into_iter().flatten() {
        add(p["value"].as_str());
    }
    for key in ["topicColors", "topics"] {
        for k in cfg[key].as_object().into_iter().flat_map(|o| o.keys()) {
            add(Some(k));
        }
    }
    assert!(!t.is_empty() || id.starts_with("3D!"), "{id} shows nothing");
    t
}

#[test]
fn the_layout_opens_and_every_topic_it_names_is_ours() {
    let l = layout();
    let configs = l["configById"].as_object().expect("configById");
    let mut panels = Vec::new();
    leaves(&l["layout"], &mut panels);
    let in_tree: BTreeSet<&str> = panels.iter().map(String::as_str).collect();
    let configured: BTreeSet<&str> = configs.keys().map(String::as_str).collect();
    assert_eq!(in_tree.len(), panels.len(), "a panel twice in the tree");
    assert_eq!(
        in_tree, configured,
        "the tree's panels are the configured ones"
    );
    let built_in = [
        "map",
        "3D",
        "Plot",
        "StateTransitions",
        "RosOut",
        "RawMessages",
    ];
    let mut ours: BTreeSet<String> = hil::live::CHANNELS
        .iter()
        .map(|c| c.topic.to_string())
        .collect();
    // the recordings' channels (nav.mcap: nav's JSON channels; truth.mcap: the bench's)
    ours.extend(
        nav::record::channels::JsonChannel::ALL
            .iter()
            .map(|c| c.topic().to_string()),
    );
    let mut shown = BTreeSet::new();
    for (id, cfg) in configs {
        let kind = id.split('!').next().unwrap_or("");
        assert!(
            built_in.contains(&kind) && id.len() > kind.len() + 1,
            "{id}: not a built-in panel's id"
        );
        for t in topics_named(id, cfg) {
            assert!(
                ours.contains(&t),
                "{id} names {t}, a channel of neither the live view nor the recordings"
            );
            shown.insert(t);
        }
    }
    // what the live view is for: the table, the heading, the map, the faults, the result
    for t in [
        "/turntable/status",
        "/turntable/command",
        "/truth/turntable",
        "/nav/event",
        "/nav/location",
        "/truth/location",
        "/bench/faults",
        "/hil/result",
        "/imu/rates",
        "/nav/status",
    ] {
        assert!(shown.contains(t), "the layout shows nothing of {t}");
    }
}
