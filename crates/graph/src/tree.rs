//! The shape a run takes: a tree of stages rooted at the source. A lone pipeline is a
//! chain (one branch); several pipelines replayed together (`relume compare`) share
//! the longest run of identical leading stages, which then fans out into one branch
//! per pipeline. Every leaf of the tree ends a branch, whose finished frames the
//! runtime hands back per frame, in order.
//!
//! Two pipelines share their first L stages: L is the length of their longest prefix
//! of identical stages (same name, kind, parameters, product bindings and virtual
//! objects; `write` stages never, as each branch saves into its own folder), cut back
//! while a stage below L reads the previous-frame product (`@prev`) of a stage at or
//! after L: a shared stage cannot take one feedback value per branch.

use super::build::build_stage;
use super::pipeline::Pipeline;
use super::registry::Registry;
use super::resolved::{DEFAULT_CHANNEL_CAPACITY, ResolvedStage};
use super::stage::{Stage, StageError};
use super::world::World;
use relume_recording::Header;
use std::path::PathBuf;
use std::sync::Arc;

/// One stage of the tree.
#[derive(Clone, Debug)]
pub struct GraphNode {
    pub stage: ResolvedStage,
    /// The world its builder receives (that of the first pipeline that has it).
    pub world: Arc<dyn World>,
    /// The node whose frames it reads (`None`: the source).
    pub parent: Option<usize>,
    /// The branches (pipelines) that run it, in order; more than one for a shared stage.
    pub branches: Vec<usize>,
    /// Why its pipeline cannot run yet ([`World::waiting`]): building fails with it
    /// rather than run without what it waits for.
    pub waiting: Option<String>,
}

/// A feedback edge between two nodes: `producer`'s `product` of frame t-1 goes to
/// `consumer` at frame t.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GraphFeedback {
    pub producer: usize,
    pub consumer: usize,
    pub product: String,
}

/// Stages as a tree, with one branch per pipeline.
#[derive(Clone, Debug)]
pub struct StageGraph {
    /// In an order where every parent comes before its children.
    pub nodes: Vec<GraphNode>,
    /// Per branch, its label (for errors and timing rows; empty for a lone pipeline).
    pub labels: Vec<String>,
    /// Per branch, the node of each of its pipeline's stages, in pipeline order.
    pub branch_nodes: Vec<Vec<usize>>,
    pub feedback: Vec<GraphFeedback>,
    /// Frames buffered between two nodes: the largest of the pipelines'.
    pub channel_capacity: usize,
}

impl StageGraph {
    /// A lone pipeline: its stages in a chain.
    pub fn linear(pipeline: &Pipeline) -> StageGraph {
        StageGraph::shared(&[(String::new(), pipeline)])
    }

    /// Several pipelines over one recording, sharing their longest identical prefixes
    /// (see the module docs). `branches` pairs each pipeline with its label.
    pub fn shared(branches: &[(String, &Pipeline)]) -> StageGraph {
        let mut graph = StageGraph {
            nodes: Vec::new(),
            labels: branches.iter().map(|(l, _)| l.clone()).collect(),
            branch_nodes: Vec::new(),
            feedback: Vec::new(),
            channel_capacity: branches
                .iter()
                .map(|(_, p)| p.channel_capacity)
                .max()
                .unwrap_or(DEFAULT_CHANNEL_CAPACITY),
        };
        for (b, (_, pipeline)) in branches.iter().enumerate() {
            let mut parent = None;
            let mut mine = Vec::new();
            let depths: Vec<usize> = branches[..b]
                .iter()
                .map(|(_, earlier)| shared_depth(earlier, pipeline))
                .collect();
            for d in 0..pipeline.stages.len() {
                let shared = graph
                    .nodes
                    .iter()
                    .position(|n| n.parent == parent && d < depths[n.branches[0]]);
                let node = match shared {
                    Some(n) => {
                        graph.nodes[n].branches.push(b);
                        n
                    }
                    None => {
                        graph.nodes.push(GraphNode {
                            stage: pipeline.stages[d].clone(),
                            world: pipeline.world.clone(),
                            parent,
                            branches: vec![b],
                            waiting: pipeline.waiting().into_iter().next(),
                        });
                        graph.nodes.len() - 1
                    }
                };
                mine.push(node);
                parent = Some(node);
            }
            for fb in &pipeline.feedback {
                let edge = GraphFeedback {
                    producer: mine[fb.producer],
                    consumer: mine[fb.consumer],
                    product: fb.product.clone(),
                };
                if !graph.feedback.contains(&edge) {
                    debug_assert!(
                        !graph
                            .feedback
                            .iter()
                            .any(|f| f.consumer == edge.consumer && f.product == edge.product),
                        "one feedback value per shared stage and product"
                    );
                    graph.feedback.push(edge);
                }
            }
            graph.branch_nodes.push(mine);
        }
        graph
    }

    /// Number of branches.
    pub fn branch_count(&self) -> usize {
        self.branch_nodes.len()
    }

    /// The last node of branch `b` (`None`: a pipeline without stages).
    pub fn branch_end(&self, b: usize) -> Option<usize> {
        self.branch_nodes[b].last().copied()
    }

    /// The nodes whose parent is `parent`, in order.
    pub fn children(&self, parent: Option<usize>) -> impl Iterator<Item = usize> + '_ {
        (0..self.nodes.len()).filter(move |&n| self.nodes[n].parent == parent)
    }

    /// The branches that run a node, as its errors name them (`a`, or `a+b` for a
    /// stage some branches share): `None` when every branch runs it.
    pub fn branch_label(&self, node: usize) -> Option<String> {
        let n = &self.nodes[node];
        if n.branches.len() == self.branch_count() {
            return None;
        }
        let labels: Vec<&str> = n
            .branches
            .iter()
            .map(|&b| self.labels[b].as_str())
            .collect();
        Some(labels.join("+"))
    }

    /// A node's name in timing rows: the stage's name, after the labels of the
    /// branches that run it (`a/name`, `a+b/name`) unless every branch does.
    pub fn row_name(&self, node: usize) -> String {
        let name = &self.nodes[node].stage.name;
        match self.branch_label(node) {
            Some(label) => format!("{label}/{name}"),
            None => name.clone(),
        }
    }

    /// Builds every node's stage. `out_dirs` holds each branch's folder for the files
    /// its stages write (a node writes into that of its first branch). On failure: the
    /// node, and why.
    pub fn build(
        &self,
        registry: &Registry,
        header: &Header,
        out_dirs: &[PathBuf],
        seed: u64,
    ) -> Result<Vec<Box<dyn Stage>>, (usize, StageError)> {
        self.nodes
            .iter()
            .enumerate()
            .map(|(i, node)| {
                build_stage(
                    &node.stage,
                    &node.world,
                    node.waiting.as_deref(),
                    registry,
                    header,
                    &out_dirs[node.branches[0]],
                    seed,
                )
                .map_err(|e| (i, e))
            })
            .collect()
    }
}

/// How many first stages `a` and `b` can share (see the module docs).
fn shared_depth(a: &Pipeline, b: &Pipeline) -> usize {
    let same_world = Arc::ptr_eq(&a.world, &b.world) || a.world.same_as(b.world.as_ref());
    // A pipeline whose world is not ready shares nothing, so that each of its nodes
    // carries the reason that stops the build.
    let ready = a.waiting().is_empty() && b.waiting().is_empty();
    if !same_world || !ready {
        return 0;
    }
    let mut depth = a
        .stages
        .iter()
        .zip(&b.stages)
        .take_while(|(x, y)| same_stage(x, y) && x.kind != "write")
        .count();
    // A shared stage fed back from an unshared one: share only what comes before it
    // (and again, for what that cut leaves unshared).
    while let Some(cut) = a
        .feedback
        .iter()
        .chain(&b.feedback)
        .filter(|fb| fb.consumer < depth && fb.producer >= depth)
        .map(|fb| fb.consumer)
        .min()
    {
        depth = cut;
    }
    depth
}

fn same_stage(x: &ResolvedStage, y: &ResolvedStage) -> bool {
    x.name == y.name
        && x.kind == y.kind
        && x.every == y.every
        && x.lag == y.lag
        && x.params == y.params
        && x.inputs == y.inputs
        && x.outputs == y.outputs
}
