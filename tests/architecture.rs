//! Architecture: the modules of each workspace crate must not import each other in a cycle.
//!
//! Every crate target (a library's `src/lib.rs`, a binary's `src/main.rs` or `src/bin/*`) is
//! parsed with `syn` from its root through its `mod name;` declarations. Nodes are modules
//! (`a/b.rs` or `a/b/mod.rs` is `crate::a::b`; `#[cfg(test)]` items are left out). Edges are
//! uses: a non-`pub` `use` of `crate::..`, `super::..`, `self::..` or a child module, and every
//! such path in code (macro bodies included; comments and string literals never count), plus
//! names brought in by a `pub use` or a glob when code uses them. A path is resolved to the
//! module that DEFINES the item, through `use` re-exports, so a `mod.rs` that only re-exports
//! its children is no node of a cycle. A `mod child;` or `pub use` declaration alone is no edge.
//! (`#[path]` attributes on `mod` are not supported: such a file is reported as unreadable.)

use proc_macro2::{Spacing, TokenStream, TokenTree};
use quote::ToTokens;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Reads a source file; `None` if it does not exist.
type Read<'a> = &'a dyn Fn(&Path) -> Option<String>;

/// One module: its place in the tree and what it declares, imports and references.
#[derive(Default)]
struct Module {
    name: String,
    file: PathBuf,
    parent: Option<usize>,
    children: BTreeMap<String, usize>,
    /// Items defined here (functions, types, traits, constants, macros...).
    defs: BTreeSet<String>,
    /// `use` bindings: name -> path.
    aliases: HashMap<String, Vec<String>>,
    /// Sources of glob imports (`use x::*`).
    globs: Vec<Vec<String>>,
    /// Paths written here (in `use` and in code), with their lines.
    refs: Vec<(Vec<String>, usize)>,
}

/// Where a path leads.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Target {
    /// A module, named as such.
    Module(usize),
    /// An item defined in this module.
    Item(usize),
    /// A name this module does not have: the path's deepest existing module.
    NotFound(usize),
    /// Another crate, the prelude, a local variable.
    Outside,
}

impl Target {
    fn module(self) -> Option<usize> {
        match self {
            Target::Module(m) | Target::Item(m) | Target::NotFound(m) => Some(m),
            Target::Outside => None,
        }
    }
}

struct Crate {
    mods: Vec<Module>,
}

fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg") && {
            let t = a.meta.to_token_stream().to_string();
            t.contains("test") && !t.contains("not")
        }
    })
}

impl Crate {
    /// Loads a crate target from its root file (e.g. `src/lib.rs`).
    fn load(root: &Path, read: Read) -> Result<Crate, String> {
        let mut c = Crate { mods: Vec::new() };
        let dir = root.parent().unwrap_or(Path::new("")).to_path_buf();
        c.load_file(root, &dir, "crate".into(), None, read)?;
        Ok(c)
    }

    fn load_file(
        &mut self,
        file: &Path,
        dir: &Path,
        name: String,
        parent: Option<usize>,
        read: Read,
    ) -> Result<usize, String> {
        let text = read(file).ok_or_else(|| format!("cannot read {}", file.display()))?;
        let ast = syn::parse_file(&text)
            .map_err(|e| format!("{}:{}: {e}", file.display(), e.span().start().line))?;
        let id = self.new_module(name, file, parent);
        self.items(id, &ast.items, dir, read)?;
        Ok(id)
    }

    fn new_module(&mut self, name: String, file: &Path, parent: Option<usize>) -> usize {
        let id = self.mods.len();
        let short = name.rsplit("::").next().unwrap_or_default().to_string();
        self.mods.push(Module {
            name,
            file: file.to_path_buf(),
            parent,
            ..Default::default()
        });
        if let Some(p) = parent {
            self.mods[p].children.insert(short, id);
        }
        id
    }

    /// Records the items of module `m`, whose child modules' files live in `dir`.
    fn items(
        &mut self,
        m: usize,
        items: &[syn::Item],
        dir: &Path,
        read: Read,
    ) -> Result<(), String> {
        for item in items {
            match item {
                syn::Item::Mod(im) if is_cfg_test(&im.attrs) => {}
                syn::Item::Mod(im) => {
                    let name = im.ident.to_string();
                    let full = format!("{}::{name}", self.mods[m].name);
                    let sub = dir.join(&name);
                    if let Some((_, inner)) = &im.content {
                        // An inline `mod x { .. }`: a module of its own, in the same file.
                        let file = self.mods[m].file.clone();
                        let id = self.new_module(full, &file, Some(m));
                        self.items(id, inner, &sub, read)?;
                    } else {
                        let flat = dir.join(format!("{name}.rs"));
                        let file = if read(&flat).is_some() {
                            flat
                        } else {
                            sub.join("mod.rs")
                        };
                        self.load_file(&file, &sub, full, Some(m), read)?;
                    }
                }
                syn::Item::Use(u) if is_cfg_test(&u.attrs) => {}
                syn::Item::Use(u) => {
                    let public = !matches!(u.vis, syn::Visibility::Inherited);
                    let line = u.use_token.span.start().line;
                    let mut leaves = Vec::new();
                    use_leaves(&u.tree, &mut Vec::new(), &mut leaves);
                    let md = &mut self.mods[m];
                    for (segs, bind) in leaves {
                        match bind.as_deref() {
                            None => md.globs.push(segs),
                            Some(b) => {
                                if !public {
                                    md.refs.push((segs.clone(), line));
                                }
                                if b != "_" {
                                    md.aliases.insert(b.to_string(), segs);
                                }
                            }
                        }
                    }
                }
                other => {
                    let (attrs, ident) = item_name(other);
                    if is_cfg_test(attrs) {
                        continue;
                    }
                    let md = &mut self.mods[m];
                    md.defs.extend(ident);
                    scan(other.to_token_stream(), &mut md.refs);
                }
            }
        }
        Ok(())
    }

    /// Resolves a path written in module `m`.
    fn resolve(&self, m: usize, segs: &[String], depth: usize) -> Target {
        let Some(first) = segs.first() else {
            return Target::Module(m);
        };
        if depth > 40 {
            return Target::Outside;
        }
        let md = &self.mods[m];
        match first.as_str() {
            "crate" => self.walk(0, &segs[1..], depth),
            "super" | "self" => self.walk(m, segs, depth),
            f if md.children.contains_key(f)
                || md.defs.contains(f)
                || md.aliases.contains_key(f) =>
            {
                self.walk(m, segs, depth)
            }
            _ => self
                .through_globs(m, segs, depth)
                .unwrap_or(Target::Outside),
        }
    }

    /// Follows `segs` down from module `m` to the module that defines the item they name.
    fn walk(&self, m: usize, segs: &[String], depth: usize) -> Target {
        let Some(s) = segs.first() else {
            return Target::Module(m);
        };
        if depth > 40 {
            return Target::NotFound(m);
        }
        let md = &self.mods[m];
        let rest = &segs[1..];
        match s.as_str() {
            "super" => match md.parent {
                Some(p) => self.walk(p, rest, depth + 1),
                None => Target::Outside,
            },
            "self" => self.walk(m, rest, depth + 1),
            _ if md.children.contains_key(s) => self.walk(md.children[s], rest, depth + 1),
            _ if md.defs.contains(s) => Target::Item(m),
            _ if md.aliases.contains_key(s) => match self.resolve(m, &md.aliases[s], depth + 1) {
                Target::Module(x) => self.walk(x, rest, depth + 1),
                t => t,
            },
            _ => self
                .through_globs(m, segs, depth)
                .unwrap_or(Target::NotFound(m)),
        }
    }

    /// Looks a path up in the sources of module `m`'s glob imports.
    fn through_globs(&self, m: usize, segs: &[String], depth: usize) -> Option<Target> {
        let md = &self.mods[m];
        let local = |f: &str| {
            matches!(f, "crate" | "super" | "self")
                || md.children.contains_key(f)
                || md.aliases.contains_key(f)
        };
        // Globs of other crates (`use std::io::*`) are not followed.
        let globs = md.globs.iter().filter(|g| local(&g[0]));
        globs
            .into_iter()
            .find_map(|g| match self.resolve(m, g, depth + 1) {
                Target::Module(src) if src != m => match self.walk(src, segs, depth + 1) {
                    Target::NotFound(_) | Target::Outside => None,
                    t => Some(t),
                },
                _ => None,
            })
    }

    /// Edges `from -> to` with the first place each is written: (file:line, path).
    fn edges(&self) -> BTreeMap<(usize, usize), (String, String)> {
        let mut edges = BTreeMap::new();
        for (m, md) in self.mods.iter().enumerate() {
            for (segs, line) in &md.refs {
                // A lone ident is a use only as a name imported by `use` or a glob; `crate`,
                // `super` and `self` alone are visibilities (`pub(crate)`) or receivers.
                let f = segs[0].as_str();
                let local = md.defs.contains(f)
                    || md.children.contains_key(f)
                    || matches!(f, "crate" | "self" | "super");
                if segs.len() == 1 && local && !md.aliases.contains_key(f) {
                    continue;
                }
                if let Some(to) = self.resolve(m, segs, 0).module() {
                    if to != m {
                        let at = format!("{}:{line}", md.file.display());
                        edges.entry((m, to)).or_insert((at, segs.join("::")));
                    }
                }
            }
        }
        edges
    }

    /// Cycles as printable chains: the shortest one through each module that is on a cycle and
    /// not yet on a reported one, so every module in a cycle shows up once at least.
    fn cycles(&self) -> Vec<String> {
        let edges = self.edges();
        let (mut out, mut covered) = (Vec::new(), BTreeSet::new());
        for start in 0..self.mods.len() {
            if covered.contains(&start) {
                continue;
            }
            // Breadth first from `start` until an edge leads back to it.
            let mut prev = vec![None; self.mods.len()];
            let mut queue = VecDeque::from([start]);
            while let Some(a) = queue.pop_front().filter(|_| prev[start].is_none()) {
                for &(_, b) in edges.range((a, 0)..(a + 1, 0)).map(|(k, _)| k) {
                    if prev[b].is_none() {
                        prev[b] = Some(a);
                        queue.push_back(b);
                    }
                }
            }
            let Some(mut at) = prev[start] else {
                continue;
            };
            let mut chain = vec![start, at];
            while at != start {
                at = prev[at].unwrap();
                chain.push(at);
            }
            chain.reverse();
            covered.extend(chain.iter().copied());
            let names: Vec<&str> = chain.iter().map(|&i| self.mods[i].name.as_str()).collect();
            let mut text = names.join(" -> ");
            for w in chain.windows(2) {
                let (at, path) = &edges[&(w[0], w[1])];
                let (a, b) = (&self.mods[w[0]].name, &self.mods[w[1]].name);
                write!(text, "\n      {a} -> {b}: `{path}` at {at}").unwrap();
            }
            out.push(text);
        }
        out
    }
}

/// The item's attributes and the name it defines, if any.
fn item_name(item: &syn::Item) -> (&[syn::Attribute], Option<String>) {
    use syn::Item::*;
    let (a, i): (&[syn::Attribute], Option<&syn::Ident>) = match item {
        Const(x) => (&x.attrs, Some(&x.ident)),
        Enum(x) => (&x.attrs, Some(&x.ident)),
        Fn(x) => (&x.attrs, Some(&x.sig.ident)),
        Macro(x) => (&x.attrs, x.ident.as_ref()),
        Static(x) => (&x.attrs, Some(&x.ident)),
        Struct(x) => (&x.attrs, Some(&x.ident)),
        Trait(x) => (&x.attrs, Some(&x.ident)),
        TraitAlias(x) => (&x.attrs, Some(&x.ident)),
        Type(x) => (&x.attrs, Some(&x.ident)),
        Union(x) => (&x.attrs, Some(&x.ident)),
        Impl(x) => (&x.attrs, None),
        ExternCrate(x) => (&x.attrs, None),
        ForeignMod(x) => (&x.attrs, None),
        _ => (&[], None),
    };
    (a, i.map(|i| i.to_string()))
}

/// The leaves of a `use` tree: (full path, bound name; `None` for a glob).
fn use_leaves(
    tree: &syn::UseTree,
    prefix: &mut Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>)>,
) {
    let with = |prefix: &Vec<String>, s: String| {
        let mut p = prefix.clone();
        if s != "self" || p.is_empty() {
            p.push(s);
        }
        p
    };
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            use_leaves(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let s = n.ident.to_string();
            let bind = if s == "self" {
                prefix.last().cloned()
            } else {
                Some(s.clone())
            };
            out.push((with(prefix, s), bind));
        }
        syn::UseTree::Rename(r) => out.push((
            with(prefix, r.ident.to_string()),
            Some(r.rename.to_string()),
        )),
        syn::UseTree::Glob(_) => out.push((prefix.clone(), None)),
        syn::UseTree::Group(g) => g.items.iter().for_each(|t| use_leaves(t, prefix, out)),
    }
}

/// Collects the paths `a::b::c` written in a token stream, with their lines. Paths after `.`
/// (fields, methods) and absolute `::a` paths are skipped; lone idents are kept (see `edges`).
fn scan(tokens: TokenStream, refs: &mut Vec<(Vec<String>, usize)>) {
    let toks: Vec<TokenTree> = tokens.into_iter().collect();
    let colons = |i: usize| {
        matches!((toks.get(i), toks.get(i + 1)), (Some(TokenTree::Punct(a)), Some(TokenTree::Punct(b)))
            if a.as_char() == ':' && a.spacing() == Spacing::Joint && b.as_char() == ':')
    };
    let mut i = 0;
    while i < toks.len() {
        match &toks[i] {
            TokenTree::Group(g) => scan(g.stream(), refs),
            TokenTree::Ident(id) => {
                let after_dot =
                    i > 0 && matches!(&toks[i - 1], TokenTree::Punct(p) if p.as_char() == '.');
                let absolute = i > 1 && colons(i - 2);
                let mut segs = vec![id.to_string()];
                while colons(i + 1) {
                    match toks.get(i + 3) {
                        Some(TokenTree::Ident(n)) => {
                            segs.push(n.to_string());
                            i += 3;
                        }
                        _ => break,
                    }
                }
                if !after_dot && !absolute {
                    refs.push((segs, id.span().start().line));
                }
            }
            _ => {}
        }
        i += 1;
    }
}

/// The crate targets of a package folder: `src/lib.rs`, `src/main.rs`, `src/bin/*`, and the
/// `path`s of its manifest's `[lib]` and `[[bin]]` sections.
fn targets(pkg: &Path) -> Vec<PathBuf> {
    let src = pkg.join("src");
    let mut roots: Vec<PathBuf> = vec![src.join("lib.rs"), src.join("main.rs")];
    if let Ok(rd) = std::fs::read_dir(src.join("bin")) {
        let mut bins: Vec<PathBuf> = rd
            .flatten()
            .map(|e| e.path())
            .map(|p| if p.is_dir() { p.join("main.rs") } else { p })
            .collect();
        bins.sort();
        roots.extend(bins);
    }
    let manifest = std::fs::read_to_string(pkg.join("Cargo.toml")).unwrap_or_default();
    let mut section = "";
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line;
        } else if (section == "[lib]" || section == "[[bin]]") && line.starts_with("path") {
            if let Some(p) = line.split('"').nth(1) {
                roots.push(pkg.join(p));
            }
        }
    }
    let mut seen = BTreeSet::new();
    roots.retain(|p| {
        p.extension().is_some_and(|e| e == "rs") && p.exists() && seen.insert(p.clone())
    });
    roots
}

/// Cycles of one crate target, each line prefixed by the target's root file.
fn target_cycles(root: &Path, label: &str, read: Read) -> Vec<String> {
    match Crate::load(root, read) {
        Ok(c) => c
            .cycles()
            .into_iter()
            .map(|c| format!("{label}: {c}"))
            .collect(),
        Err(e) => vec![format!("{label}: could not read the module tree: {e}")],
    }
}

/// The workspace's member folders, from the `members` list of its `Cargo.toml`
/// (every crate is checked, including crates added later).
fn workspace_members(ws: &Path) -> Vec<String> {
    let manifest = std::fs::read_to_string(ws.join("Cargo.toml")).expect("workspace Cargo.toml");
    let start = manifest.find("members").expect("a members list");
    let list = &manifest[start..];
    let list = &list[list.find('[').unwrap() + 1..list.find(']').unwrap()];
    list.split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty() && m != "tests")
        .collect()
}

#[test]
fn no_import_cycles_between_modules() {
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    // Paths relative to the workspace, so the report reads `amc-server/src/cli.rs:30`.
    let read = |p: &Path| std::fs::read_to_string(ws.join(p)).ok();
    let mut found = Vec::new();
    let mut checked = 0;
    for pkg in workspace_members(ws) {
        for root in targets(&ws.join(&pkg)) {
            checked += 1;
            let root = root.strip_prefix(ws).unwrap();
            found.extend(target_cycles(root, &root.display().to_string(), &read));
        }
    }
    assert!(
        checked >= 7,
        "found only {checked} crate targets under {}",
        ws.display()
    );
    assert!(
        found.is_empty(),
        "modules import each other in cycles ({} shown: together they pass through every \
         module on a cycle; each is the chain, then where each of its edges is written):\n  {}\n",
        found.len(),
        found.join("\n  ")
    );
}

// ------------------------------------------------------------------ the checker's own tests

fn fixture_cycles(files: &[(&str, &str)]) -> Vec<String> {
    let map: HashMap<PathBuf, String> = files
        .iter()
        .map(|(p, t)| (PathBuf::from(p), t.to_string()))
        .collect();
    let read = |p: &Path| map.get(p).cloned();
    let c = Crate::load(Path::new("src/lib.rs"), &read).unwrap();
    c.cycles()
        .into_iter()
        .map(|s| s.lines().next().unwrap().to_string())
        .collect()
}

#[test]
fn checker_passes_an_acyclic_tree() {
    let cycles = fixture_cycles(&[
        (
            "src/lib.rs",
            "mod a; mod b; pub use a::A; fn f() -> b::B { b::make(A) }",
        ),
        (
            "src/a.rs",
            "pub struct A; // crate::b::B in a comment\nconst S: &str = \"crate::b::B\";",
        ),
        (
            "src/b.rs",
            "use crate::a::A; pub(super) struct B; pub(crate) fn make(_: A) -> B { B }",
        ),
    ]);
    assert!(cycles.is_empty(), "{cycles:?}");
}

#[test]
fn checker_finds_a_two_cycle() {
    let cycles = fixture_cycles(&[
        ("src/lib.rs", "mod a; mod b;"),
        ("src/a.rs", "use crate::b::B; pub struct A(pub B);"),
        (
            "src/b.rs",
            "pub struct B; fn f() -> Option<crate::a::A> { println!(\"{}\", 1); None }",
        ),
    ]);
    assert_eq!(cycles, ["crate::a -> crate::b -> crate::a"]);
    // A parent using its child's item while the child uses the parent's item is a cycle too.
    let cycles = fixture_cycles(&[
        ("src/lib.rs", "mod m;"),
        ("src/m/mod.rs", "mod c; pub struct P; fn f() { c::g(); }"),
        ("src/m/c.rs", "pub fn g() -> super::P { super::P }"),
    ]);
    assert_eq!(cycles, ["crate::m -> crate::m::c -> crate::m"]);
}

#[test]
fn checker_finds_a_three_cycle() {
    let cycles = fixture_cycles(&[
        (
            "src/lib.rs",
            "mod a; mod b; mod c;\n#[cfg(test)]\nmod tests;",
        ),
        ("src/a.rs", "pub fn a() { crate::b::b() }"),
        ("src/b.rs", "use crate::c; pub fn b() { c::c() }"),
        (
            "src/c.rs",
            "pub fn c() { format!(\"{:?}\", super::a::a()); }",
        ),
    ]);
    assert_eq!(cycles, ["crate::a -> crate::b -> crate::c -> crate::a"]);
}

#[test]
fn checker_sees_through_re_exports() {
    // `shapes` only re-exports its children; `circle` uses `super::Square` (defined in
    // `square`); the root uses `shapes::Circle` (defined in `circle`): no cycle.
    let cycles = fixture_cycles(&[
        ("src/lib.rs", "mod shapes; pub use shapes::*; pub fn area(c: &Circle) -> f64 { c.0.side }"),
        ("src/shapes/mod.rs", "mod circle; mod square; pub use circle::Circle; pub use square::Square;"),
        ("src/shapes/circle.rs", "use super::Square; pub struct Circle(pub Square);"),
        ("src/shapes/square.rs", "pub struct Square { pub side: f64 }\n#[cfg(test)]\nmod tests { use crate::shapes::Circle; }"),
    ]);
    assert!(cycles.is_empty(), "{cycles:?}");
    // Once the hub uses a child's item in its own code, and the child its own item, it cycles.
    let cycles = fixture_cycles(&[
        ("src/lib.rs", "mod shapes;"),
        (
            "src/shapes/mod.rs",
            "mod circle; pub use circle::Circle; pub struct Unit; fn f(_: Circle) {}",
        ),
        (
            "src/shapes/circle.rs",
            "pub struct Circle(pub super::Unit);",
        ),
    ]);
    assert_eq!(
        cycles,
        ["crate::shapes -> crate::shapes::circle -> crate::shapes"]
    );
}

// ------------------------------------------------------------------ crates by job

/// The `amc-*` crates a member's `[dependencies]` names (dev-dependencies left out).
fn amc_dependencies(ws: &Path, pkg: &str) -> Vec<String> {
    let manifest = std::fs::read_to_string(ws.join(pkg).join("Cargo.toml")).unwrap();
    let mut section = String::new();
    let mut deps = Vec::new();
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line.to_string();
        } else if section == "[dependencies]" && line.starts_with("amc-") {
            deps.push(line.split([' ', '=', '.']).next().unwrap().to_string());
        }
    }
    deps
}

#[test]
fn crates_depend_one_way_by_job() {
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    // Each crate and the crates it may build on: the algorithm, then video I/O, the run
    // engine, then evaluation and the service side by side, the command line last.
    let allowed: &[(&str, &[&str])] = &[
        ("amc-core", &[]),
        ("amc-synth", &["amc-core"]),
        ("amc-video", &["amc-core"]),
        // Gyro logs from bytes: the engine's and the page's.
        ("amc-gyrolog", &["amc-core"]),
        ("amc-engine", &["amc-core", "amc-video", "amc-gyrolog"]),
        (
            "amc-eval",
            &["amc-core", "amc-video", "amc-engine", "amc-synth"],
        ),
        ("amc-server", &["amc-core", "amc-video", "amc-engine"]),
        (
            "amc-cli",
            &[
                "amc-core",
                "amc-video",
                "amc-engine",
                "amc-eval",
                "amc-server",
            ],
        ),
        ("amc-wasm", &["amc-core", "amc-gyrolog"]),
    ];
    let members = workspace_members(ws);
    let mut wrong = Vec::new();
    for pkg in &members {
        let Some((_, may)) = allowed.iter().find(|(name, _)| name == pkg) else {
            wrong.push(format!(
                "{pkg}: a new crate: give it its place in this test"
            ));
            continue;
        };
        for dep in amc_dependencies(ws, pkg) {
            if !may.contains(&dep.as_str()) {
                wrong.push(format!("{pkg} depends on {dep}"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "dependencies against the layering:\n  {}",
        wrong.join("\n  ")
    );
}

#[test]
fn engine_and_service_leave_out_the_cli_and_plot_stacks() {
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let banned: &[(&str, &[&str])] = &[
        (
            "amc-core",
            &["axum", "sqlx", "object_store", "clap", "plotters", "tokio"],
        ),
        (
            "amc-engine",
            &["axum", "sqlx", "object_store", "clap", "plotters"],
        ),
        ("amc-server", &["clap", "plotters"]),
        ("amc-eval", &["axum", "sqlx", "object_store", "clap"]),
    ];
    for (pkg, names) in banned {
        let out = std::process::Command::new(&cargo)
            .args(["tree", "-p", pkg, "-e", "normal", "--prefix", "none"])
            .current_dir(ws)
            .output()
            .expect("cargo tree runs");
        assert!(
            out.status.success(),
            "cargo tree -p {pkg}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let tree = String::from_utf8_lossy(&out.stdout);
        for name in *names {
            let found = tree.lines().any(|l| l.split(' ').next() == Some(name));
            assert!(!found, "{pkg}'s dependency tree holds {name}");
        }
    }
}
