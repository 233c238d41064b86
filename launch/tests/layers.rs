//! The launcher's modules import one way: no module reaches, through `crate::…`, a module that
//! reaches back to it (docs/architecture.md, "The launcher").

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, into: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            sources(&path, into);
        } else if path.extension().is_some_and(|e| e == "rs") {
            into.push(path);
        }
    }
}

/// The crate's top-level modules and the top-level modules each one names through `crate::`.
fn imports(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    sources(src, &mut files);
    let top = |path: &Path| {
        let rel = path.strip_prefix(src).expect("under src");
        let first = rel.components().next().expect("a component");
        let name = first.as_os_str().to_string_lossy();
        name.trim_end_matches(".rs").to_string()
    };
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        graph.entry(top(file)).or_default();
    }
    let modules: BTreeSet<String> = graph.keys().cloned().collect();
    for file in &files {
        let from = top(file);
        let text = std::fs::read_to_string(file).expect("read source");
        let mut named = BTreeSet::new();
        for (i, _) in text.match_indices("crate::") {
            let rest = &text[i + "crate::".len()..];
            if let Some(group) = rest.strip_prefix('{') {
                let inside = &group[..group.find('}').unwrap_or(group.len())];
                named.extend(
                    inside
                        .split(',')
                        .map(|p| p.trim().split("::").next().unwrap_or("")),
                );
            } else {
                named.insert(
                    rest.split(|c: char| !c.is_alphanumeric() && c != '_')
                        .next()
                        .unwrap_or(""),
                );
            }
        }
        let these = graph.get_mut(&from).expect("module");
        these.extend(
            named
                .into_iter()
                .filter(|m| modules.contains(*m) && *m != from)
                .map(str::to_string),
        );
    }
    graph
}

/// A cycle through `from`, if the graph has one (depth-first search).
fn cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut found = path[at..].to_vec();
            found.push(node.to_string());
            return Some(found);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in &graph[node] {
            if let Some(found) = visit(next, graph, path, done) {
                return Some(found);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

#[test]
fn the_launchers_modules_import_one_way() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let graph = imports(&src);
    assert!(graph.len() > 20, "found the modules: {:?}", graph.keys());
    assert!(
        graph["up"].contains("supervisor") && graph["replay"].contains("up"),
        "the scan sees imports: {graph:?}"
    );
    if let Some(found) = cycle(&graph) {
        panic!(
            "an import cycle among the launcher's modules: {}",
            found.join(" -> ")
        );
    }
    // The errors are the bottom layer.
    assert!(
        graph["error"].is_empty(),
        "error imports {:?}",
        graph["error"]
    );
}
