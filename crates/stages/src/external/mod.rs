//! `external`: a stage that is a user's program, in any language, started once per run
//! and fed one frame at a time over its standard input and output (protocol 1,
//! `docs/external-stages.md`; the Python side is `python/relume_stage`).
//!
//! The pipeline table declares the ports, so `relume validate` checks an external stage
//! as it checks a built-in one:
//!
//! ```toml
//! [[stage]]
//! kind = "external"
//! name = "scale"
//! inputs = { image = "depth" }
//! params = { interpreter = "python3", program = "scale.py",
//!            input_kinds = ["image=depth"], output_kinds = ["scaled=depth"],
//!            settings = ["gain=0.5"] }
//! ```
//!
//! Images travel through shared memory (`shm`) when the program maps it, else over the
//! pipe. The reply's `compute_ms` (the program's own time) is reported apart from the
//! rest, the transport. Poses travel in the meta. Not yet: other products than images
//! and poses, and ports declared by the program.

mod images;
mod program;
pub mod protocol;
mod shm;

use crate::kind;
use program::{Program, Stopped};
use protocol::{ImageMeta, Layout, ReadError, Reply, Request, ShmOffer, Value};
use relume_graph::{
    BuildContext, Frame, ParamDefault, ParamSpec, Params, Port, Ports, Stage, StageError, StageInfo,
};
use relume_recording::Pose;
use shm::SharedMemory;
use std::collections::BTreeMap;
use std::io::Write;
use std::time::Duration;

pub const INFO: StageInfo = StageInfo {
    kind: "external",
    summary: "a program of your own, in any language, fed one frame at a time \
              (docs/external-stages.md)",
    params: &[
        ParamSpec::new(
            "program",
            ParamDefault::Str(""),
            "the program (or the script its interpreter runs), relative to the pipeline \
             file; required",
        )
        .file_path(),
        ParamSpec::new(
            "interpreter",
            ParamDefault::Str(""),
            "what runs `program` (e.g. python3, found on PATH); empty: run `program` itself",
        )
        .checked(one_word),
        ParamSpec::new(
            "input_kinds",
            ParamDefault::StrList(&[]),
            "the images the program reads, each `role=kind`; kinds: color, depth, points, \
             normals, radiance, scalar, labels",
        )
        .checked(port_declaration),
        ParamSpec::new(
            "output_kinds",
            ParamDefault::StrList(&[]),
            "the images the program writes, each `role=kind` (kinds as for input_kinds)",
        )
        .checked(port_declaration),
        ParamSpec::new(
            "settings",
            ParamDefault::StrList(&[]),
            "the program's own parameters, each `name=value`, sent to it as written",
        )
        .checked(setting),
        ParamSpec::new(
            "transport",
            ParamDefault::Str("auto"),
            "how images travel: auto offers shared memory (used when the program maps it, \
             as relume_stage does), pipe sends every byte over the pipe",
        )
        .choices(&["auto", "pipe"]),
        ParamSpec::new(
            "timeout_s",
            ParamDefault::Float(60.0),
            "seconds the program may take on a frame (and to start) before it is stopped",
        )
        .range(0.001, 86_400.0),
    ],
    ports,
    build,
};

fn one_word(s: &str) -> Result<(), String> {
    if s.chars().any(char::is_whitespace) {
        return Err(format!(
            "{s:?} is more than one word: name one program (its arguments go in `settings`)"
        ));
    }
    Ok(())
}

/// `role=kind`, the role a name and the kind one relume sends.
fn port_declaration(s: &str) -> Result<(), String> {
    let (role, kind) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?} is not `role=kind`"))?;
    if role.is_empty() || !role.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!(
            "the role {role:?} must be letters, digits and underscores"
        ));
    }
    if Layout::of(kind).is_none() && kind != protocol::POSE {
        let mut kinds: Vec<&str> = protocol::LAYOUTS.iter().map(|l| l.name).collect();
        kinds.push(protocol::POSE);
        return Err(format!(
            "{kind:?} is not a kind an external stage exchanges: {}",
            kinds.join(", ")
        ));
    }
    Ok(())
}

fn setting(s: &str) -> Result<(), String> {
    match s.split_once('=') {
        Some((name, _)) if !name.is_empty() => Ok(()),
        _ => Err(format!("{s:?} is not `name=value`")),
    }
}

/// The `role=kind` items of the list `name`, checked when the pipeline was loaded.
fn role_kinds<'p>(params: &'p Params, name: &str) -> impl Iterator<Item = (&'p str, &'p str)> {
    params
        .str_list(name)
        .iter()
        .filter_map(|d| d.split_once('='))
}

/// The declared image ports.
fn declared(params: &Params, name: &str) -> Vec<(String, Layout)> {
    role_kinds(params, name)
        .filter_map(|(role, kind)| Some((role.to_string(), Layout::of(kind)?)))
        .collect()
}

/// The declared ports of kind `pose`.
fn declared_poses(params: &Params, name: &str) -> Vec<String> {
    role_kinds(params, name)
        .filter(|(_, kind)| *kind == protocol::POSE)
        .map(|(role, _)| role.to_string())
        .collect()
}

fn ports(params: &Params) -> Ports {
    let port =
        |(role, layout): (String, Layout)| Port::new(&role, &role, images::product_kind(&layout));
    let pose = |role: String| Port::new(&role, &role, &[kind::POSE]);
    let side = |name: &str| -> Vec<Port> {
        declared(params, name)
            .into_iter()
            .map(port)
            .chain(declared_poses(params, name).into_iter().map(pose))
            .collect()
    };
    Ports {
        inputs: side("input_kinds"),
        outputs: side("output_kinds"),
    }
}

/// The programs a pipeline's stages start: (stage name, command line), in stage order.
/// A run names them before it starts them; `relume validate` lists them.
pub fn programs(stages: &[relume_graph::ResolvedStage]) -> Vec<(String, String)> {
    stages
        .iter()
        .filter(|s| s.kind == INFO.kind)
        .map(|s| (s.name.clone(), command(&s.params).join(" ")))
        .collect()
}

/// The command line an external stage's parameters run: interpreter, then program.
pub fn command(params: &Params) -> Vec<String> {
    let mut command = Vec::new();
    if !params.str("interpreter").is_empty() {
        command.push(params.str("interpreter").to_string());
    }
    // `program` is a path (resolved against the pipeline's folder): one without a
    // slash must not be looked up on PATH.
    let program = params.str("program");
    if std::path::Path::new(program).components().count() == 1 && !program.starts_with('/') {
        command.push(format!("./{program}"));
    } else {
        command.push(program.to_string());
    }
    command
}

fn build(ctx: &BuildContext) -> Result<Box<dyn Stage>, StageError> {
    let params = ctx.params;
    if params.str("program").is_empty() {
        return Err(StageError::Failed(
            "parameter `program` is required: the program to run, or the script its \
             `interpreter` runs"
                .into(),
        ));
    }
    // The image ports and the pose ports (product, role) of one side, bound to products.
    let bind = |name: &str, product: &dyn Fn(&str) -> String| {
        let images: Vec<Bound> = declared(params, name)
            .into_iter()
            .map(|(role, layout)| Bound {
                product: product(&role),
                role,
                layout,
            })
            .collect();
        let poses: Vec<(String, String)> = declared_poses(params, name)
            .into_iter()
            .map(|role| (product(&role), role))
            .collect();
        (images, poses)
    };
    let (inputs, pose_inputs) = bind("input_kinds", &|role| ctx.input(role));
    let (outputs, pose_outputs) = bind("output_kinds", &|role| ctx.output(role));
    let kinds = |bound: &[Bound], poses: &[(String, String)]| -> BTreeMap<String, String> {
        bound
            .iter()
            .map(|b| (b.role.clone(), b.layout.name.to_string()))
            .chain(
                poses
                    .iter()
                    .map(|(_, role)| (role.clone(), protocol::POSE.to_string())),
            )
            .collect()
    };
    let settings = params
        .str_list("settings")
        .iter()
        .filter_map(|s| s.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let (width, height) = (
        ctx.header.color_intrinsics.width,
        ctx.header.color_intrinsics.height,
    );
    let frame_bytes = |bound: &[Bound]| -> usize {
        bound
            .iter()
            .map(|b| {
                (width as usize * height as usize)
                    * (b.layout.channels as u64 * b.layout.dtype.size()) as usize
            })
            .sum()
    };
    let (input_bytes, output_bytes) = (frame_bytes(&inputs), frame_bytes(&outputs));
    let mut shm = match params.str("transport") {
        "auto" if input_bytes + output_bytes > 0 => Some(
            SharedMemory::create(ctx.stage_name, input_bytes, output_bytes).map_err(|e| {
                StageError::Failed(format!(
                    "cannot make shared memory for the program (transport = \"pipe\" does \
                     without): {e}"
                ))
            })?,
        ),
        _ => None,
    };
    let offer = shm.as_ref().and_then(|m| {
        Some(ShmOffer {
            path: m.path()?.to_string_lossy().into_owned(),
            size: m.len() as u64,
            output_offset: m.output_offset as u64,
        })
    });
    let hello = Request::Hello {
        protocol: protocol::VERSION,
        stage: ctx.stage_name.to_string(),
        settings,
        inputs: kinds(&inputs, &pose_inputs),
        outputs: kinds(&outputs, &pose_outputs),
        seed: ctx.seed,
        shm: offer,
    };
    let timeout = Duration::from_secs_f64(params.float("timeout_s"));
    let mut program =
        Program::start(ctx.stage_name, &command(params)).map_err(StageError::Failed)?;
    let reply = program.within(timeout, |p| {
        let stdin = p.stdin.as_mut().expect("open until the end");
        protocol::write_meta(stdin, &hello)
            .and_then(|()| stdin.flush())
            .map_err(ReadError::Io)?;
        protocol::read_meta::<Reply>(&mut p.stdout)
    });
    let fail = |why: String| StageError::Failed(format!("`{}`: {why}", program.command_line));
    match reply {
        Ok(Ok(Reply::Ready {
            protocol,
            transport,
        })) if protocol == protocol::VERSION => {
            // Mapped by the program, or not wanted: either way the file can go.
            if transport.as_deref() != Some("shm") {
                shm = None;
            }
            if let Some(shm) = &mut shm {
                shm.unlink();
            }
        }
        Ok(Ok(Reply::Ready { protocol, .. })) => {
            return Err(fail(format!(
                "the program speaks protocol {protocol}; this relume speaks {}: update one \
                 of the two",
                protocol::VERSION
            )));
        }
        Ok(Ok(Reply::Error { message })) => {
            return Err(fail(format!("the program refused to start: {message}")));
        }
        Ok(Ok(other)) => {
            return Err(fail(format!(
                "the program answered `hello` with {other:?}, not `ready`"
            )));
        }
        Ok(Err(ReadError::Malformed(why))) => {
            return Err(fail(format!("the program's answer to `hello` is {why}")));
        }
        Ok(Err(ReadError::Closed { .. } | ReadError::Io(_))) => {
            let death = program.death();
            return Err(StageError::Failed(format!(
                "`{}`: {death}",
                program.command_line
            )));
        }
        Err(Stopped::TimedOut) => {
            let tail = program.stderr_tail();
            return Err(fail(format!(
                "the program did not answer `hello` within {} s (timeout_s) and was \
                 stopped{tail}",
                params.float("timeout_s")
            )));
        }
        Err(Stopped::Interrupted) => {
            return Err(fail(
                "interrupted while the program started: it was stopped".into(),
            ));
        }
    }
    Ok(Box::new(External {
        stage: ctx.stage_name.to_string(),
        seed: ctx.seed,
        program: Some(program),
        inputs,
        outputs,
        timeout,
        size: (width, height),
        shm,
        program_ns: None,
        pose_inputs,
        pose_outputs,
    }))
}

/// A declared port and the product it is bound to.
struct Bound {
    role: String,
    product: String,
    layout: Layout,
}

struct External {
    stage: String,
    seed: u64,
    /// `None` once the program failed: it was stopped.
    program: Option<Program>,
    inputs: Vec<Bound>,
    outputs: Vec<Bound>,
    timeout: Duration,
    /// The frame's image size, which every output must have.
    size: (u32, u32),
    /// The shared memory the program mapped, if it did.
    shm: Option<SharedMemory>,
    /// The program's own time on the last frame, from its reply.
    program_ns: Option<u64>,
    /// The pose ports: (product, role).
    pose_inputs: Vec<(String, String)>,
    pose_outputs: Vec<(String, String)>,
}

/// The per-frame seed a program is given: hash(run seed, frame, stage name).
pub fn frame_seed(run_seed: u64, frame: u64, stage: &str) -> u64 {
    let stage = xxhash_rust::xxh3::xxh3_64(stage.as_bytes());
    relume_base::rng::hash(&[run_seed, frame, stage])
}

impl Stage for External {
    fn process(&mut self, frame: &mut Frame) -> Result<(), StageError> {
        let mut metas = Vec::with_capacity(self.inputs.len());
        let mut blobs = Vec::with_capacity(self.inputs.len());
        for input in &self.inputs {
            let product = frame
                .get(&input.product)
                .ok_or_else(|| StageError::MissingInput(input.product.clone()))?;
            let (meta, bytes) =
                images::to_bytes(product, &input.role, &input.layout).ok_or_else(|| {
                    StageError::WrongKind {
                        product: input.product.clone(),
                        expected: images::product_kind(&input.layout)[0].name(),
                        found: product.kind().name(),
                    }
                })?;
            metas.push(meta);
            blobs.push(bytes);
        }
        if let Some(shm) = &mut self.shm {
            // Declared inputs at the frame's size fit the region; others go by pipe.
            let mut offset = 0;
            for (meta, bytes) in metas.iter_mut().zip(&mut blobs) {
                if offset + bytes.len() <= shm.output_offset {
                    shm.write(offset, bytes);
                    meta.offset = Some(offset as u64);
                    offset += bytes.len();
                    *bytes = &[];
                }
            }
        }
        let mut values = Vec::with_capacity(self.pose_inputs.len());
        for (product, role) in &self.pose_inputs {
            let pose: &Pose = frame.get_as(product, kind::POSE)?;
            values.push(Value {
                role: role.clone(),
                kind: protocol::POSE.into(),
                translation: Some(pose.translation),
                rotation: Some(pose.rotation),
            });
        }
        let index = frame.index as u64;
        let request = Request::Frame {
            index,
            stamp_ns: frame.stamp_ns,
            seed: frame_seed(self.seed, index, &self.stage),
            inputs: metas,
            values,
        };
        let program = self.program.as_mut().ok_or_else(|| {
            StageError::Failed("the program was stopped by an earlier error".into())
        })?;
        let outputs = &self.outputs;
        let pose_outputs = &self.pose_outputs;
        let size = self.size;
        let shm = &self.shm;
        let exchange = program.within(self.timeout, |p| -> Result<_, Fault> {
            let stdin = p.stdin.as_mut().expect("open until the end");
            let sent = protocol::write_meta(stdin, &request).and_then(|()| {
                for blob in &blobs {
                    stdin.write_all(blob)?;
                }
                stdin.flush()
            });
            sent.map_err(|e| Fault::Read(ReadError::Io(e)))?;
            let reply = protocol::read_meta::<Reply>(&mut p.stdout).map_err(Fault::Read)?;
            let (metas, values, compute_ms) = match reply {
                Reply::Frame {
                    index: i,
                    outputs,
                    values,
                    compute_ms,
                } if i == index => (outputs, values, compute_ms),
                Reply::Frame { index: i, .. } => {
                    return Err(Fault::Reply(format!(
                        "the reply is for frame {i}, not {index}"
                    )));
                }
                Reply::Error { message } => {
                    return Err(Fault::Reply(format!("the program failed: {message}")));
                }
                Reply::Ready { .. } => {
                    return Err(Fault::Reply(
                        "the program answered a frame with `ready`".into(),
                    ));
                }
            };
            let ports = check_outputs(&metas, outputs, size).map_err(Fault::Reply)?;
            let poses = check_poses(&values, pose_outputs).map_err(Fault::Reply)?;
            // The images follow in the reply's order.
            let mut products = Vec::with_capacity(metas.len());
            for (meta, port) in metas.iter().zip(ports) {
                let bound = &outputs[port];
                let product = match meta.offset {
                    None => images::from_reader(meta, &bound.layout, &mut p.stdout),
                    Some(offset) => {
                        let len = meta.byte_len().map_err(Fault::Reply)?;
                        let bytes = shm
                            .as_ref()
                            .and_then(|m| m.slice(usize::try_from(offset).ok()?, len))
                            .ok_or_else(|| {
                                Fault::Reply(format!(
                                    "`{}` lies at bytes {offset}..+{len} of a shared memory \
                                     of {} bytes",
                                    meta.role,
                                    shm.as_ref().map_or(0, |m| m.len())
                                ))
                            })?;
                        images::from_reader(meta, &bound.layout, &mut &bytes[..])
                    }
                }
                .map_err(Fault::Read)?;
                products.push((bound.product.clone(), product));
            }
            for (pose, (product, _)) in poses.into_iter().zip(pose_outputs) {
                products.push((
                    product.clone(),
                    relume_graph::Product::new(kind::POSE, pose),
                ));
            }
            Ok((products, compute_ms))
        });
        let products = match exchange {
            Ok(Ok((products, compute_ms))) => {
                // A time the program cannot have taken is not reported.
                self.program_ns = compute_ms
                    .filter(|ms| ms.is_finite() && *ms >= 0.0 && *ms < 86_400_000.0)
                    .map(|ms| (ms * 1e6) as u64);
                products
            }
            Ok(Err(fault)) => {
                let mut program = self.program.take().expect("present above");
                let why = match fault {
                    Fault::Read(ReadError::Closed { .. } | ReadError::Io(_)) => program.death(),
                    Fault::Read(ReadError::Malformed(why)) => format!("its reply is {why}"),
                    Fault::Reply(why) => why,
                };
                return Err(StageError::Failed(format!(
                    "`{}`: {why}",
                    program.command_line
                )));
            }
            Err(Stopped::TimedOut) => {
                let program = self.program.take().expect("present above");
                return Err(StageError::Failed(format!(
                    "`{}`: no reply within {} s (timeout_s): the program was stopped{}",
                    program.command_line,
                    self.timeout.as_secs_f64(),
                    program.stderr_tail()
                )));
            }
            Err(Stopped::Interrupted) => {
                let program = self.program.take().expect("present above");
                return Err(StageError::Failed(format!(
                    "`{}`: interrupted while the program worked: it was stopped",
                    program.command_line
                )));
            }
        };
        for (name, product) in products {
            frame.insert(&name, product);
        }
        Ok(())
    }

    fn program_ns(&self) -> Option<u64> {
        self.program_ns
    }

    fn finish(&mut self) -> Result<(), StageError> {
        let Some(mut program) = self.program.take() else {
            return Ok(());
        };
        let sent = program.within(self.timeout, |p| {
            let stdin = p.stdin.as_mut().expect("open until the end");
            protocol::write_meta(stdin, &Request::End).and_then(|()| stdin.flush())
        });
        let status = program.finish();
        match (sent, status) {
            (Ok(Ok(())), Some(status)) if status.success() => Ok(()),
            (_, Some(status)) => Err(StageError::Failed(format!(
                "`{}`: after the last frame the program {}{}",
                program.command_line,
                program::describe(status),
                program.stderr_tail()
            ))),
            (_, None) => Err(StageError::Failed(format!(
                "`{}`: the program did not exit after the last frame and was stopped",
                program.command_line
            ))),
        }
    }
}

/// The reply's poses in the order of the declared pose outputs: each once, finite, its
/// rotation a unit quaternion; otherwise what is wrong.
fn check_poses(values: &[Value], outputs: &[(String, String)]) -> Result<Vec<Pose>, String> {
    for value in values {
        if !outputs.iter().any(|(_, role)| *role == value.role) {
            return Err(format!(
                "the reply holds the value `{}`, which is not a declared pose output",
                value.role
            ));
        }
    }
    let mut poses = Vec::with_capacity(outputs.len());
    for (_, role) in outputs {
        let mut given = values.iter().filter(|v| v.role == *role);
        let value = given
            .next()
            .ok_or_else(|| format!("the reply lacks the output `{role}`"))?;
        if given.next().is_some() {
            return Err(format!("the reply holds `{role}` twice"));
        }
        let (Some(translation), Some(rotation), protocol::POSE) =
            (value.translation, value.rotation, value.kind.as_str())
        else {
            return Err(format!(
                "`{role}` is declared a pose: kind \"pose\" with a translation [x, y, z] and \
                 a rotation [x, y, z, w]"
            ));
        };
        if translation
            .iter()
            .chain(&rotation)
            .any(|v| !v.is_finite() || v.abs() > 1e4)
        {
            return Err(format!(
                "`{role}` holds {translation:?}, {rotation:?}: not finite or beyond 10 km"
            ));
        }
        let norm = rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(format!(
                "`{role}`'s rotation {rotation:?} has length {norm:.4}, not 1: not a unit \
                 quaternion"
            ));
        }
        poses.push(Pose {
            translation,
            rotation,
        });
    }
    Ok(poses)
}

/// What went wrong in an exchange.
enum Fault {
    Read(ReadError),
    Reply(String),
}

/// For each image of the reply, in its order, the index of the declared output it is:
/// every declared output once, each of its declared kind and the frame's size;
/// otherwise what is wrong.
fn check_outputs(
    metas: &[ImageMeta],
    outputs: &[Bound],
    (width, height): (u32, u32),
) -> Result<Vec<usize>, String> {
    let mut ports = Vec::with_capacity(metas.len());
    for meta in metas {
        meta.byte_len()?;
        let Some(port) = outputs.iter().position(|o| o.role == meta.role) else {
            let declared: Vec<&str> = outputs.iter().map(|o| o.role.as_str()).collect();
            return Err(format!(
                "the reply holds `{}`, which is not a declared output ({})",
                meta.role,
                declared.join(", ")
            ));
        };
        if ports.contains(&port) {
            return Err(format!("the reply holds `{}` twice", meta.role));
        }
        let layout = &outputs[port].layout;
        if meta.kind != layout.name
            || meta.channels != layout.channels
            || meta.dtype != layout.dtype
        {
            return Err(format!(
                "`{}` is {} with {} {} channels; it is declared {} ({} {} channels)",
                meta.role,
                meta.kind,
                meta.channels,
                meta.dtype.name(),
                layout.name,
                layout.channels,
                layout.dtype.name()
            ));
        }
        if (meta.width, meta.height) != (width, height) {
            return Err(format!(
                "`{}` is {}x{}; the frame's images are {width}x{height}",
                meta.role, meta.width, meta.height
            ));
        }
        ports.push(port);
    }
    if let Some(missing) = outputs.iter().enumerate().find(|(i, _)| !ports.contains(i)) {
        return Err(format!("the reply lacks the output `{}`", missing.1.role));
    }
    Ok(ports)
}
