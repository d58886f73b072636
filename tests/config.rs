//! Pipeline configs: unknown kinds, parameters, roles, wrong types, out-of-range values
//! and products nobody produces are load-time errors with file, line, column and hint.

use relume::graph::{ConfigError, Params, Pipeline, SourceFile};
use relume::recording::{Header, Intrinsics};
use relume::stages::world::PipelineObjects;

fn load(text: &str) -> Result<Pipeline, ConfigError> {
    Pipeline::parse(
        &SourceFile {
            name: "pipelines/p.toml".into(),
            text: text.into(),
        },
        &relume::stages::registry(),
    )
}

fn error(text: &str) -> ConfigError {
    load(text).expect_err("the config is rejected")
}

#[test]
fn unknown_kind_suggests_the_closest() {
    let e = error("[[stage]]\nkind = \"decode\"\n\n[[stage]]\nkind = \"normals.crss\"\n");
    assert_eq!(
        (e.file.as_str(), e.line, e.column),
        ("pipelines/p.toml", 5, 8)
    );
    assert_eq!(e.message, "unknown stage kind `normals.crss`");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `normals.cross`? `relume stages` lists every kind")
    );
    assert!(
        e.to_string()
            .contains("5 | kind = \"normals.crss\"\n  |        ^^^^^^^^^^^^^^"),
        "{e}"
    );
}

#[test]
fn unknown_parameter_names_the_key_and_lists_the_parameters() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\nparams = { stpe = 2 }\n",
    );
    assert_eq!((e.line, e.column), (7, 12));
    assert_eq!(
        e.message,
        "unknown parameter `stpe` for stage `normals.cross` (normals.cross)"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `step`? parameters of normals.cross: step, difference, max_depth_jump")
    );
}

#[test]
fn wrong_types_ranges_and_choices_are_located() {
    let head = "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\n";
    let e = error(&format!("{head}params = {{ step = \"two\" }}\n"));
    assert_eq!(
        (e.line, e.message.as_str()),
        (7, "parameter `step` must be an integer, found a string")
    );
    let e = error(&format!("{head}params = {{ step = 40 }}\n"));
    assert_eq!(e.message, "parameter `step` = 40 is out of range (1 to 16)");
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"write\"\nparams = { products = [\"color\", \"depth\",\n  \"color\"] }\n",
    );
    assert_eq!(
        (e.line, e.column, e.message.as_str()),
        (6, 3, "parameter `products` names \"color\" twice")
    );
    let e = error(&format!("{head}params = {{ difference = \"centrl\" }}\n"));
    assert_eq!(
        e.message,
        "parameter `difference` does not accept \"centrl\""
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean \"central\"? choices: forward, central")
    );
    // A float parameter accepts an integer.
    load(&format!("{head}params = {{ max_depth_jump = 1 }}\n")).unwrap();

    // A string with a form of its own is checked at load time too, not first at run.
    let impostor = "[[stage]]\nkind = \"light.impostor\"\n";
    let e = error(&format!("{impostor}params = {{ center = \"1,2\" }}\n"));
    assert_eq!((e.line, e.column), (3, 21));
    assert_eq!(
        e.message,
        "center = \"1,2\" is not three comma-separated finite numbers x,y,z"
    );
    let e = error(&format!(
        "{impostor}params = {{ center = \"1e30, 0, 0\" }}\n"
    ));
    assert_eq!(
        e.message,
        "center = \"1e30, 0, 0\" lies more than 10000 m from the origin along an axis"
    );
    // A good centre passes; what is left is the stage's unfed input.
    let e = error(&format!(
        "{impostor}params = {{ center = \" 1, 2.5 ,-3\" }}\n"
    ));
    assert!(e.message.contains("no upstream stage produces it"), "{e}");
}

/// Two stages that read each other's products in one frame get a hint naming the
/// cycle, not "move that stage up" (which would then be said of the other one).
#[test]
fn stages_reading_each_other_are_named_as_a_cycle() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"refined\" }\n[[stage]]\nkind = \"normals.plane_fit\"\noutputs = { refined_depth = \"refined\" }\n",
    );
    assert_eq!(
        e.message,
        "stage `depth.to_points` reads `refined` as its `depth` input, but no upstream stage produces it"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some(
            "these stages form a cycle (`depth.to_points` reads `refined` from `normals.plane_fit`, `normals.plane_fit` reads `points` from `depth.to_points`): no order of them runs; one of them must read the other's product of the previous frame (`@prev`, on an input that can do without it at the first frame)"
        )
    );
    // Through a third stage, and on an input that can do without: the previous
    // frame's value is offered.
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"gbuffer.splat\"\ninputs = { cloud = \"cloud\" }\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"reference_depth\" }\n[[stage]]\nkind = \"normals.plane_fit\"\n[[stage]]\nkind = \"cloud.samples\"\ninputs = { depth = \"refined_depth\" }\n",
    );
    let hint = e.hint.unwrap_or_default();
    assert!(
        hint.starts_with(
            "these stages form a cycle (`gbuffer.splat` reads `cloud` from `cloud.samples`, "
        ) && hint.contains("`depth.to_points` reads `reference_depth` from `gbuffer.splat`")
            && hint.ends_with("read `cloud@prev` here for its previous-frame value"),
        "{hint}"
    );
}

#[test]
fn inputs_must_be_produced_upstream() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"normals.cross\"\n[[stage]]\nkind = \"depth.to_points\"\n",
    );
    assert_eq!(
        e.line, 4,
        "points at the stage's kind when the input is not mapped"
    );
    assert_eq!(
        e.message,
        "stage `normals.cross` reads `points` as its `points` input, but no upstream stage produces it"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("`points` is produced later, by stage `depth.to_points`: move that stage up")
    );
    // Only an input the stage can do without may read the previous frame: the first
    // frame has none.
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.cross\"\ninputs = { points = \"points@prev\" }\n",
    );
    assert_eq!((e.line, e.column), (7, 21));
    assert_eq!(
        e.message,
        "stage `normals.cross` cannot read `points@prev` as its `points` input: it needs that input at every frame, and the first frame has no previous one"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("read `points` from this frame, produced upstream")
    );
    // gbuffer.splat does without its cloud, so the hint offers the previous frame's.
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"gbuffer.splat\"\ninputs = { cloud = \"cloud\" }\n[[stage]]\nkind = \"depth.to_points\"\n[[stage]]\nkind = \"normals.plane_fit\"\n[[stage]]\nkind = \"cloud.samples\"\ninputs = { depth = \"refined_depth\" }\n",
    );
    assert_eq!(
        e.hint.as_deref(),
        Some(
            "`cloud` is produced later, by stage `cloud.samples`: move that stage up, or read `cloud@prev` for its previous-frame value"
        )
    );

    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"dpeth\" }\n",
    );
    assert_eq!((e.line, e.column), (5, 20));
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `depth`? products available here: color, depth, pose, record")
    );
}

#[test]
fn kinds_of_products_must_match() {
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"normals.cross\"\ninputs = { points = \"depth\" }\n",
    );
    assert_eq!(
        e.message,
        "stage `normals.cross` reads `depth` as its `points` input, but `depth` is a depth map; it needs a point map"
    );
}

#[test]
fn roles_names_and_products_are_checked() {
    let e = error("[[stage]]\nkind = \"decode\"\noutputs = { colour = \"c\" }\n");
    assert_eq!(e.message, "stage `decode` has no output `colour`");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `color`? outputs of this stage: color, depth, pose")
    );
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"decode\"\ninputs = { record = \"record\" }\n",
    );
    assert_eq!(
        e.message,
        "a second stage named `decode` (the first is on line 1)"
    );
    let e = error("[[stage]]\nname = \" \"\nkind = \"decode\"\n");
    assert_eq!(
        (e.line, e.message.as_str(), e.hint.as_deref()),
        (
            2,
            "a stage name may not be blank: errors and timing tables name stages by it",
            Some("leave `name` out to use the kind, `decode`")
        )
    );
    let e = error("[[stage]]\nkind = \"decode\"\n[[stage]]\nname = \"again\"\nkind = \"decode\"\n");
    assert_eq!(
        e.message,
        "stage `again` writes product `color`, which stage `decode` already produces"
    );
    let e = error(
        "[[stage]]\nkind = \"decode\"\n[[stage]]\nkind = \"depth.to_points\"\ninputs = { depth = \"record@prev\" }\n",
    );
    assert!(
        e.message.starts_with(
            "stage `depth.to_points` reads `record` as its `depth` input, but `record` is a record"
        ),
        "{e}"
    );
}

#[test]
fn structure_errors() {
    assert_eq!(error("").message, "the pipeline has no stages");
    let e = error("[pipeline]\nchannel_capacity = 0\n[[stage]]\nkind = \"decode\"\n");
    assert_eq!(
        (e.line, e.message.as_str()),
        (2, "channel_capacity must be between 1 and 1024, got 0")
    );
    let e = error("[[stage]]\nname = \"x\"\n");
    assert_eq!(e.message, "this stage has no `kind`");
    let e = error("[pipline]\n");
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `pipeline`? allowed: pipeline, stage, object, light")
    );
}

#[test]
fn every_builtin_kind_builds_from_its_defaults() {
    let registry = relume::stages::registry();
    // The light stages need an environment attachment and a place for the object.
    let mut header = Header::new("t", Intrinsics::PRIMESENSE, 0.001);
    header.ground_truth = Some(relume::recording::SceneTruth {
        object_position: [0.0, 0.3, 0.0],
        description: String::new(),
    });
    header.attachments.push(relume::recording::Attachment {
        name: "environment".into(),
        kind: "envmap/latlong".into(),
        image: relume::recording::codec::encode_floats(8, 4, 3, &[1.0; 96], false),
    });
    let dir = tempfile::tempdir().unwrap();
    for info in registry.kinds() {
        let params = Params::defaults(info.params);
        let ports = (info.ports)(&params);
        let names = |ports: &[relume::graph::Port]| {
            ports
                .iter()
                .map(|p| (p.role.clone(), p.default_product.clone()))
                .collect()
        };
        let (inputs, outputs) = (names(&ports.inputs), names(&ports.outputs));
        let ctx = relume::graph::BuildContext {
            stage_name: info.kind,
            params: &params,
            inputs: &inputs,
            outputs: &outputs,
            header: &header,
            out_dir: dir.path(),
            seed: 1,
            world: &relume::stages::world::world_of(relume::objects::VirtualScene::default()),
        };
        match (info.build)(&ctx) {
            // An external stage is a program the pipeline names: it has none by default.
            Err(e) if info.kind == "external" => assert_eq!(
                e.to_string(),
                "parameter `program` is required: the program to run, or the script its \
                 `interpreter` runs"
            ),
            built => assert!(built.is_ok(), "{} builds from its defaults", info.kind),
        }
        assert!(
            !info.summary.is_empty() && info.params.iter().all(|p| !p.doc.is_empty()),
            "{} is documented",
            info.kind
        );
    }
}

const DECODE: &str = "[[stage]]\nkind = \"decode\"\n";

#[test]
fn objects_resolve_into_the_world_space_scene() {
    let p = load(&format!(
        "{DECODE}
[[object]]
name = \"torus\"
shape = \"torus\"
major_radius = 0.25
minor_radius = 0.08
translation = [0.0, 0.08, 0.0]
rotation_deg = [0.0, 0.0, 0.0]
albedo = [0.8, 0.3, 0.2]
exponent = 0

[[object]]
shape = \"sphere\"
radius = 0.1
segments = 16
translation = [1, 0.1, -1]
exponent = 20

[[object]]
shape = \"box\"
size = [0.2, 0.4, 0.2]
rotation_deg = [0, 45, 0]
translation = [-1, 0.2, 0]
scale = 2
"
    ))
    .unwrap();
    let scene = &p.objects();
    // 64 x 32 x 2 torus, 2 x 16 x 7 sphere, 12 box triangles.
    assert_eq!(scene.triangles.len(), 4096 + 224 + 12);
    assert!(scene.bvh.is_built_for(scene.triangles.len()));
    assert_eq!(scene.materials.len(), 3);
    assert_eq!(scene.materials[0].albedo.to_array(), [0.8, 0.3, 0.2]);
    assert_eq!(scene.materials[1].exponent, 20.0);
    assert_eq!(scene.materials[2].albedo.to_array(), [0.7; 3]);
    let b = scene.bounds();
    // The box, doubled to 0.4 x 0.8 x 0.4 and turned 45 degrees: half-diagonal 0.2 sqrt 2.
    let half_diagonal = 0.2 * 2f32.sqrt();
    assert!((b.min.x - (-1.0 - half_diagonal)).abs() < 1e-5, "{b:?}");
    assert!((b.min.y - -0.2).abs() < 1e-6, "{b:?}");
    assert!((b.max.x - 1.1).abs() < 1e-6, "{b:?}");
    assert!((b.max.y - 0.6).abs() < 1e-6, "{b:?}");
    assert!((b.min.z - -1.1).abs() < 1e-6, "{b:?}");
    assert!((b.max.z - 0.33).abs() < 1e-6, "{b:?}");
    // The torus lies on the floor: a ray down onto its tube stops at y = 0.16.
    let hit = scene
        .intersect(
            glam::Vec3::new(0.25, 1.0, 0.0),
            glam::Vec3::NEG_Y,
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert!((hit.t - 0.84).abs() < 1e-4, "{}", hit.t);

    // No [[object]]: an empty scene.
    assert!(load(DECODE).unwrap().objects().is_empty());
}

#[test]
fn mesh_paths_resolve_against_the_pipeline_directory() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("meshes")).unwrap();
    std::fs::write(
        dir.path().join("meshes/pyramid.obj"),
        "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nv 0.5 1 0.5\nf 1 2 3 4\nf 1 5 2\nf 2 5 3\nf 3 5 4\nf 4 5 1\n",
    )
    .unwrap();
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        format!(
            "{DECODE}[[object]]\nname = \"pyramid\"\nshape = \"mesh\"\npath = \"meshes/pyramid.obj\"\nscale = 0.5\ntranslation = [1, 0, 0]\n"
        ),
    )
    .unwrap();
    let p = Pipeline::load(&pipeline, &relume::stages::registry()).unwrap();
    assert_eq!(p.objects().triangles.len(), 6, "a quad base and four sides");
    let b = p.objects().bounds();
    assert_eq!(b.min.to_array(), [1.0, 0.0, 0.0]);
    assert_eq!(b.max.to_array(), [1.5, 0.5, 0.5]);

    // A mesh with an index past its vertices is rejected at the path, naming the file.
    std::fs::write(
        dir.path().join("meshes/bad.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    )
    .unwrap();
    let text = format!(
        "{DECODE}[[object]]\nname = \"bad\"\nshape = \"mesh\"\npath = \"meshes/bad.obj\"\n"
    );
    std::fs::write(&pipeline, &text).unwrap();
    let e = Pipeline::load(&pipeline, &relume::stages::registry()).unwrap_err();
    let mesh = dir.path().join("meshes/bad.obj");
    assert_eq!(
        e.message,
        format!(
            "object `bad`: the mesh `{}` is not a valid OBJ file: line 4 (`f 1 2 4`): face vertex index out of bounds",
            mesh.display()
        )
    );
    assert_eq!((e.line, e.column), (6, 8));

    // An empty file has no triangles.
    std::fs::write(dir.path().join("meshes/bad.obj"), "# nothing\n").unwrap();
    let e = Pipeline::load(&pipeline, &relume::stages::registry()).unwrap_err();
    assert_eq!(
        e.message,
        format!(
            "object `bad`: the mesh `{}` has no triangles",
            mesh.display()
        )
    );
}

#[test]
fn file_parameters_resolve_against_the_pipeline_directory_as_meshes_do() {
    let path_of = |text: &str| {
        let p = load(&format!(
            "{DECODE}[[stage]]\nkind = \"light.envmap\"\n{text}"
        ))
        .unwrap();
        let stage = p.stages.iter().find(|s| s.kind == "light.envmap").unwrap();
        stage.params.str("path").to_string()
    };
    let relative = "params = { source = \"file\", path = \"maps/probe.exr\" }\n";
    assert_eq!(path_of(relative), "pipelines/maps/probe.exr");
    let absolute = "params = { source = \"file\", path = \"/data/probe.exr\" }\n";
    assert_eq!(path_of(absolute), "/data/probe.exr");
    assert_eq!(path_of(""), "", "no path: nothing to resolve");
}

#[test]
fn object_errors_are_located_and_explained() {
    let object = |body: &str| error(&format!("{DECODE}[[object]]\nname = \"ball\"\n{body}"));
    let e = object("shape = \"sphere\"\nradus = 0.2\n");
    assert_eq!((e.line, e.column), (6, 1));
    assert_eq!(e.message, "unknown key `radus` for object `ball` (sphere)");
    assert_eq!(
        e.hint.as_deref(),
        Some(
            "did you mean `radius`? keys of a sphere: radius, segments; of every object: name, shape, translation, rotation_deg, scale, albedo, exponent, anchor, at_pixel, frame, keyframes, keyframe_translation, keyframe_rotation_deg, velocity"
        )
    );
    // A key of another shape is unknown too.
    let e = object("shape = \"box\"\nradius = 0.2\n");
    assert_eq!(e.message, "unknown key `radius` for object `ball` (box)");

    let e = object("shape = \"sphre\"\n");
    assert_eq!(
        (e.line, e.column, e.message.as_str()),
        (5, 9, "unknown shape `sphre`")
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("did you mean `sphere`? shapes: sphere, box, torus, quad, mesh")
    );
    let e = object("radius = 1\n");
    assert_eq!(e.message, "this object has no `shape`");

    let e = object("shape = \"sphere\"\nradius = \"big\"\n");
    assert_eq!(
        e.message,
        "`radius` of object `ball` must be a float, found a string"
    );
    assert_eq!(e.hint.as_deref(), Some("metres; default 0.25"));
    let e = object("shape = \"sphere\"\nsegments = 4.5\n");
    assert_eq!(
        e.message,
        "`segments` of object `ball` must be an integer, found a float"
    );
    let e = object("shape = \"sphere\"\ntranslation = 1.0\n");
    assert_eq!(
        e.message,
        "`translation` of object `ball` must be an array of 3 numbers, found a float"
    );
    let e = object("shape = \"sphere\"\ntranslation = [0, 1]\n");
    assert_eq!(
        e.message,
        "`translation` of object `ball` must be an array of 3 numbers, found 2"
    );
    let e = object("shape = \"sphere\"\nalbedo = [0.5, \"red\", 0.5]\n");
    assert_eq!((e.line, e.column), (6, 16));
    assert_eq!(
        e.message,
        "`albedo` of object `ball` must hold numbers, found a string"
    );
    let e = object("shape = \"sphere\"\nalbedo = [0.5, 1.5, 0.5]\n");
    assert_eq!((e.line, e.column), (6, 16));
    assert_eq!(
        e.message,
        "`albedo` of object `ball` = 1.5 is out of range (0 to 1)"
    );
    assert!(
        e.to_string()
            .contains("6 | albedo = [0.5, 1.5, 0.5]\n  |                ^^^"),
        "{e}"
    );
    let e = object("shape = \"sphere\"\nradius = 0\n");
    assert_eq!(
        e.message,
        "`radius` of object `ball` = 0 is out of range (0.0001 to 1000)"
    );
    let e = object("shape = \"torus\"\nmajor_radius = 0.1\nminor_radius = 0.1\n");
    assert_eq!((e.line, e.column), (7, 16));
    assert_eq!(
        e.message,
        "`minor_radius` (0.1) of object `ball` must be smaller than `major_radius` (0.1)"
    );

    let e = object("shape = \"mesh\"\n");
    assert_eq!(e.message, "object `ball` is a mesh but has no `path`");
    let e = object("shape = \"mesh\"\npath = \"no/such.obj\"\n");
    assert_eq!((e.line, e.column), (6, 8));
    assert_eq!(
        e.message,
        "object `ball`: cannot read the mesh `pipelines/no/such.obj`: No such file or directory (os error 2)"
    );
    assert_eq!(
        e.hint.as_deref(),
        Some("relative paths resolve against the pipeline file's directory (`pipelines`)")
    );

    let e = error(&format!(
        "{DECODE}[[object]]\nshape = \"box\"\n\n[[object]]\nshape = \"box\"\n"
    ));
    assert_eq!((e.line, e.column), (7, 9));
    assert_eq!(
        e.message,
        "a second object named `box` (the first is on line 3)"
    );
    let e = error(&format!("object = 3\n{DECODE}"));
    assert_eq!(
        e.message,
        "`object` must be an array of tables, written [[object]]"
    );
}

#[test]
fn object_paths_are_read_and_checked() {
    use relume::stages::world::object_world;
    let torus = "[[object]]\nname = \"torus\"\nshape = \"torus\"\nminor_radius = 0.09\n";
    let pipeline = load(&format!(
        "{DECODE}{torus}keyframes = [0, 30]\nkeyframe_translation = [[-0.5, 0.09, 0.0], [0.5, 0.09, 0.0]]\n"
    ))
    .unwrap();
    let world = object_world(&pipeline.world);
    assert!(world.moves());
    let center_x = |frame: u64| world.scene_at(frame).unwrap().bounds().center().x;
    // Frame 0's scene is the pipeline's scene; halfway the torus is at the origin,
    // and after the last keyframe it stays there.
    assert!((center_x(0) + 0.5).abs() < 1e-5 && pipeline.objects().bounds().center().x < -0.49);
    assert!(center_x(15).abs() < 1e-5, "{}", center_x(15));
    assert!((center_x(99) - 0.5).abs() < 1e-5);
    assert!(world.same_at(30, 99) && !world.same_at(14, 15));

    // A velocity: metres per frame from `translation`.
    let pipeline = load(&format!(
        "{DECODE}{torus}translation = [0.0, 0.09, 0.0]\nvelocity = [0.0, 0.0, 0.01]\n"
    ))
    .unwrap();
    let world = object_world(&pipeline.world);
    let z = world.scene_at(10).unwrap().bounds().center().z;
    assert!((z - 0.1).abs() < 1e-5, "{z}");

    // A still pipeline has no motion, and its scene is the same allocation each frame.
    let still = load(&format!("{DECODE}{torus}")).unwrap();
    let world = object_world(&still.world);
    assert!(!world.moves());
    assert!(std::sync::Arc::ptr_eq(
        &world.scene_at(7).unwrap(),
        &world.scene
    ));

    let e = error(&format!("{DECODE}{torus}keyframes = [0, 30]\n"));
    assert_eq!(
        (e.line, e.message.as_str()),
        (7, "object `torus` has `keyframes` but no poses for them")
    );
    let e = error(&format!(
        "{DECODE}{torus}keyframes = [0, 30]\nkeyframe_translation = [[0, 0, 0]]\n"
    ));
    assert_eq!(
        (e.line, e.column, e.message.as_str()),
        (
            8,
            24,
            "`keyframe_translation` of object `torus` has 1 pose for 2 keyframes"
        )
    );
    let e = error(&format!(
        "{DECODE}{torus}keyframes = [30, 0]\nkeyframe_rotation_deg = [[0, 0, 0], [0, 90, 0]]\n"
    ));
    assert_eq!(
        e.message,
        "object `torus`: keyframes must be in ascending frame order: frame 0 follows frame 30"
    );
    let e = error(&format!(
        "{DECODE}{torus}keyframes = [0, 3]\nkeyframe_translation = [[0, 0, 0], [0, 0]]\n"
    ));
    assert_eq!(
        (e.line, e.column, e.message.as_str()),
        (
            8,
            36,
            "each item of `keyframe_translation` of object `torus` must be [x, y, z], found an array"
        )
    );
    let e = error(&format!(
        "{DECODE}{torus}translation = [0, 0, 0]\nkeyframes = [0, 3]\nkeyframe_translation = [[0, 0, 0], [1, 0, 0]]\n"
    ));
    assert_eq!(
        (e.line, e.message.as_str()),
        (
            7,
            "object `torus` has both `translation` and `keyframe_translation`"
        )
    );
    let e = error(&format!(
        "{DECODE}{torus}velocity = [0, 0, 1]\nkeyframes = [0, 3]\nkeyframe_translation = [[0, 0, 0], [1, 0, 0]]\n"
    ));
    assert_eq!(
        e.message,
        "object `torus` has both `velocity` and `keyframes`"
    );
    let e = error(&format!(
        "{DECODE}{torus}keyframes = [3]\nkeyframe_translation = [[0, 0, 0]]\n"
    ));
    assert_eq!(e.message, "object `torus` has a single keyframe");
    let e = error(&format!("{DECODE}{torus}velocity = [0, 0, 0]\n"));
    assert_eq!(e.message, "`velocity` of object `torus` is zero");
    let e = error(&format!(
        "{DECODE}{torus}keyframes = [0, 9]\nkeyframe_rotation_deg = [[0, 0, 0], [0, 270, 0]]\n"
    ));
    assert!(
        e.message.contains("turn by 270 degrees about one axis"),
        "{}",
        e.message
    );
    let e = error(&format!(
        "{DECODE}{torus}keyframe_translation = [[0, 0, 0]]\n"
    ));
    assert_eq!(
        e.message,
        "`keyframe_translation` of object `torus` needs `keyframes`"
    );
}

#[test]
fn an_input_read_where_made_does_not_stop_a_pipeline_that_makes_none() {
    // temporal.accumulate reads the renderer's mask only where objects move: the
    // default with its renderer's mask renamed (nothing makes `mask`) still loads.
    let default = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/pipelines/default.toml"
    ))
    .unwrap();
    let renamed = default
        .replace(
            "touched = \"fresh_touched\"\n",
            "touched = \"fresh_touched\"\nmask = \"path_mask\"\n",
        )
        .replace(
            "kind = \"composite.differential\"\n",
            "kind = \"composite.differential\"\ninputs = { mask = \"path_mask\" }\n",
        );
    assert_ne!(renamed, default);
    let p = load(&renamed).unwrap();
    let accumulate = p
        .stages
        .iter()
        .find(|s| s.kind == "temporal.accumulate")
        .unwrap();
    assert_eq!(accumulate.inputs["mask"], "mask");
    // Bound to a product no stage makes, it is still an error, as any input is.
    let e = error(&renamed.replace(
        "kind = \"temporal.accumulate\"\n",
        "kind = \"temporal.accumulate\"\ninputs = { mask = \"patch_mask\" }\n",
    ));
    assert!(e.message.contains("patch_mask"), "{}", e.message);
}
