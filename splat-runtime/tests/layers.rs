//! The layers' dependency rules, read from ARCHITECTURE.md's table under "Layers": each crate of
//! the workspace may depend on the splat crates its row names and on no other. A crate that
//! gains an edge it must not have (the contract on a backend, the GPU backend on the CPU
//! pipeline, IO on training) fails here, naming the edge; a new crate fails until it has a row.

mod architecture;

use std::collections::BTreeMap;
use std::process::Command;

/// Each crate's row of ARCHITECTURE.md's table under `## Layers`: its name and the splat crates
/// it may depend on ("-" for none; a note in parentheses, like "(feature `gpu`)", is dropped).
fn rules(doc: &str) -> BTreeMap<String, Vec<String>> {
    architecture::fenced_block(doc, "Layers")
        .lines()
        .skip(2) // the fence's end of line and the header
        .filter_map(|line| {
            let (name, deps) = line.trim().split_once(char::is_whitespace)?;
            let deps = deps
                .split(',')
                .map(|d| d.split('(').next().unwrap().trim())
                .filter(|d| !d.is_empty() && *d != "-")
                .map(str::to_string)
                .collect();
            Some((name.to_string(), deps))
        })
        .collect()
}

/// Each workspace crate's dependencies on other workspace crates (not dev-dependencies), from
/// `cargo metadata`'s JSON.
fn workspace_edges(metadata: &serde_json::Value) -> BTreeMap<String, Vec<String>> {
    let packages = metadata["packages"].as_array().expect("packages");
    let names: Vec<&str> = packages.iter().filter_map(|p| p["name"].as_str()).collect();
    packages
        .iter()
        .map(|p| {
            let deps = p["dependencies"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|d| d["kind"].as_str() != Some("dev"))
                .filter_map(|d| d["name"].as_str())
                .filter(|d| names.contains(d))
                .map(str::to_string)
                .collect();
            (p["name"].as_str().unwrap().to_string(), deps)
        })
        .collect()
}

/// Every edge the rules do not allow, as "a -> b", and every crate without a row.
fn violations(
    edges: &BTreeMap<String, Vec<String>>,
    rules: &BTreeMap<String, Vec<String>>,
) -> Vec<String> {
    let mut out = vec![];
    for (krate, deps) in edges {
        let Some(allowed) = rules.get(krate) else {
            out.push(format!("{krate} has no row in the rules"));
            continue;
        };
        for dep in deps.iter().filter(|d| !allowed.contains(d)) {
            out.push(format!("{krate} -> {dep}"));
        }
    }
    out
}

#[test]
fn every_crate_depends_only_on_the_layers_below_it() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let edges = workspace_edges(&metadata);
    assert!(edges.len() >= 14, "{} workspace crates found", edges.len());
    let bad = violations(&edges, &rules(&architecture::text()));
    assert!(bad.is_empty(), "edges the layers forbid: {bad:#?}");
}

#[test]
fn a_forbidden_edge_is_named() {
    let table = "## Layers\n```\ncrate  may depend on\nsplat-core   -\nsplat-gpu    splat-core (feature `x`)\nsplat-cpu    splat-core, splat-io\n```\n";
    let rules = rules(table);
    assert_eq!(rules["splat-core"], Vec::<String>::new());
    assert_eq!(rules["splat-gpu"], ["splat-core"]);
    assert_eq!(rules["splat-cpu"], ["splat-core", "splat-io"]);
    let metadata = serde_json::json!({"packages": [
        {"name": "splat-core", "dependencies": [
            {"name": "splat-gpu", "kind": null},
            {"name": "splat-cpu", "kind": "dev"},
            {"name": "glam", "kind": null},
        ]},
        {"name": "splat-gpu", "dependencies": [{"name": "splat-core", "kind": null}]},
        {"name": "splat-cpu", "dependencies": []},
        {"name": "splat-new", "dependencies": []},
    ]});
    assert_eq!(
        violations(&workspace_edges(&metadata), &rules),
        [
            "splat-core -> splat-gpu",
            "splat-new has no row in the rules"
        ]
    );
}
