//! Stages that read each other's products in the same frame: no order of the stages
//! runs them, so "move that stage up" would send the user round in circles. The
//! pipeline's check names the cycle instead.

use super::product::ProductKind;
use super::resolved::{PREVIOUS_SUFFIX, ResolvedStage};
use std::collections::{BTreeMap, VecDeque};

/// The same-frame reads that lead from stage `from` back to stage `to`, if any, as
/// (reader, product, producer) steps; each stage's `@prev` inputs are not same-frame
/// reads. `producers` maps each product to the stage that writes it.
pub(super) fn read_chain(
    stages: &[ResolvedStage],
    producers: &BTreeMap<String, (usize, ProductKind)>,
    from: usize,
    to: usize,
) -> Option<Vec<(usize, String, usize)>> {
    // Breadth-first over "reads from", with the step that reached each stage.
    let mut reached: BTreeMap<usize, (usize, String)> = BTreeMap::new();
    let mut queue = VecDeque::from([from]);
    while let Some(reader) = queue.pop_front() {
        for product in stages[reader].inputs.values() {
            if product.ends_with(PREVIOUS_SUFFIX) {
                continue;
            }
            let Some(&(producer, _)) = producers.get(product) else {
                continue;
            };
            if producer >= stages.len() || producer == from || reached.contains_key(&producer) {
                continue; // the source, or a stage already reached
            }
            reached.insert(producer, (reader, product.clone()));
            if producer == to {
                let mut chain = Vec::new();
                let mut at = to;
                while at != from {
                    let (reader, product) = reached[&at].clone();
                    chain.push((reader, product, at));
                    at = reader;
                }
                chain.reverse();
                return Some(chain);
            }
            queue.push_back(producer);
        }
    }
    None
}

/// "`A` reads `x` from `B`, `B` reads `y` from `A`" for the steps of a cycle.
pub(super) fn describe(stages: &[ResolvedStage], steps: &[(usize, String, usize)]) -> String {
    steps
        .iter()
        .map(|(reader, product, producer)| {
            format!(
                "`{}` reads `{product}` from `{}`",
                stages[*reader].name, stages[*producer].name
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}
