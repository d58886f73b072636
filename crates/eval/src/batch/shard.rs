//! Which items a shard runs: those whose id hashes (xxh3) to the shard's index modulo
//! the shard count. An item's shard depends on its id alone, never on its place in the
//! manifest, so adding or removing items moves no other item between shards.
//!
//! `--shard auto` takes the index and count from the scheduler:
//! - Slurm job arrays: `SLURM_ARRAY_TASK_ID`, and `SLURM_ARRAY_TASK_COUNT` (or, where
//!   only they are set, `SLURM_ARRAY_TASK_MIN`/`SLURM_ARRAY_TASK_MAX`); an array that
//!   starts at 1 (`--array=1-4`) or steps (`SLURM_ARRAY_TASK_STEP`) is numbered from
//!   its minimum in steps.
//! - Kubernetes Indexed Jobs: `JOB_COMPLETION_INDEX`. Kubernetes sets no variable with
//!   the count, so it comes from `--shards N` or the variable [`SHARDS_VAR`]
//!   (`RELUME_SHARDS`), the Job's `completions`.

use super::error::BatchError;
use xxhash_rust::xxh3::xxh3_64;

/// The variable that gives `--shard auto` the shard count where the scheduler does not
/// (a Kubernetes Indexed Job): `RELUME_SHARDS=N`, like `--shards N`.
pub const SHARDS_VAR: &str = "RELUME_SHARDS";

/// One shard of `count`: the items whose id hashes to `index` modulo `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 0-based, below `count`.
    pub index: u64,
    /// At least 1.
    pub count: u64,
}

impl Shard {
    /// Every item: one shard of one.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Whether the item with id `id` belongs to this shard.
    pub fn contains(&self, id: &str) -> bool {
        shard_of(id, self.count) == self.index
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The shard (of `count`) that the item with id `id` belongs to: xxh3 of the id's
/// bytes, modulo `count`.
pub fn shard_of(id: &str, count: u64) -> u64 {
    xxh3_64(id.as_bytes()) % count.max(1)
}

/// The items of `items` (each with the id `id` gives) that `shard` runs, in their order.
pub fn select<T>(items: &[T], id: impl Fn(&T) -> &str, shard: Shard) -> Vec<&T> {
    items
        .iter()
        .filter(|item| shard.contains(id(item)))
        .collect()
}

/// A `--shard` value as given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSpec {
    /// `I/N`.
    Fixed(Shard),
    /// `auto`: from the scheduler's variables, see [`resolve_auto`].
    Auto,
}

impl ShardSpec {
    /// Parses `I/N` (0-based index below the count) or `auto`.
    pub fn parse(text: &str) -> Result<ShardSpec, BatchError> {
        if text == "auto" {
            return Ok(ShardSpec::Auto);
        }
        let bad = |why: String| BatchError::Shard(format!("invalid --shard {text:?}: {why}"));
        let expected =
            || bad("expected I/N (the 0-based index I of N shards, e.g. 0/4) or auto".into());
        let (i, n) = text.split_once('/').ok_or_else(expected)?;
        let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
        if !digits(i) || !digits(n) {
            return Err(expected());
        }
        let (Ok(index), Ok(count)) = (i.parse::<u64>(), n.parse::<u64>()) else {
            return Err(bad("the numbers are too large".into()));
        };
        Ok(ShardSpec::Fixed(checked(index, count).map_err(bad)?))
    }
}

/// `index` of `count`, or why not.
fn checked(index: u64, count: u64) -> Result<Shard, String> {
    if count == 0 {
        return Err("the shard count must be at least 1".into());
    }
    if index >= count {
        return Err(format!(
            "index {index} is not below the shard count {count} (shards are numbered 0 to {})",
            count - 1
        ));
    }
    Ok(Shard { index, count })
}

/// The shard that `--shard auto` stands for, read through `env` (the process
/// environment, or a table in tests), with `shards` from `--shards N`; and a line saying
/// where it came from. See the module documentation for the variables.
pub fn resolve_auto(
    env: &dyn Fn(&str) -> Option<String>,
    shards: Option<u64>,
) -> Result<(Shard, String), BatchError> {
    let err = |m: String| BatchError::Shard(format!("--shard auto: {m}"));
    let number = |name: &str| -> Result<Option<u64>, BatchError> {
        match env(name) {
            None => Ok(None),
            Some(v) => v
                .trim()
                .parse::<u64>()
                .map(Some)
                .map_err(|_| err(format!("{name}={v:?} is not a whole number"))),
        }
    };
    let from_var = number(SHARDS_VAR)?.map(|n| (n, format!("{SHARDS_VAR}={n}")));
    let given = match shards {
        Some(n) => Some((n, format!("--shards {n}"))),
        None => from_var,
    };
    if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
        let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
        let scheduler = match (
            number("SLURM_ARRAY_TASK_COUNT")?,
            number("SLURM_ARRAY_TASK_MAX")?,
        ) {
            (Some(n), _) => Some((n, format!("SLURM_ARRAY_TASK_COUNT={n}"))),
            (None, Some(max)) if max >= min => Some((
                (max - min) / step + 1,
                format!("SLURM_ARRAY_TASK_MIN={min} to SLURM_ARRAY_TASK_MAX={max}"),
            )),
            (None, _) => None,
        };
        let (count, count_from) = agree(scheduler, given, "SLURM_ARRAY_TASK_ID").map_err(err)?;
        if id < min || (id - min) % step != 0 {
            return Err(err(format!(
                "SLURM_ARRAY_TASK_ID={id} is not in the array from SLURM_ARRAY_TASK_MIN={min} \
                 in steps of {step}"
            )));
        }
        let index = (id - min) / step;
        let shard = checked(index, count).map_err(|why| {
            err(format!(
                "SLURM_ARRAY_TASK_ID={id} gives shard {index} of {count} ({count_from}): {why}"
            ))
        })?;
        return Ok((shard, format!("SLURM_ARRAY_TASK_ID={id}, {count_from}")));
    }
    if let Some(index) = number("JOB_COMPLETION_INDEX")? {
        let (count, count_from) = agree(None, given, "JOB_COMPLETION_INDEX").map_err(err)?;
        let shard = checked(index, count).map_err(|why| {
            err(format!(
                "JOB_COMPLETION_INDEX={index} of {count} ({count_from}): {why}"
            ))
        })?;
        return Ok((shard, format!("JOB_COMPLETION_INDEX={index}, {count_from}")));
    }
    Err(err(
        "neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor JOB_COMPLETION_INDEX (a \
         Kubernetes Indexed Job) is set; give --shard I/N instead"
            .into(),
    ))
}

/// The shard count from the scheduler or as given (`--shards`, [`SHARDS_VAR`]): an
/// error when they disagree, or when neither says.
fn agree(
    scheduler: Option<(u64, String)>,
    given: Option<(u64, String)>,
    index_var: &str,
) -> Result<(u64, String), String> {
    match (scheduler, given) {
        (Some((a, from_a)), Some((b, from_b))) if a != b => {
            Err(format!("{from_b} disagrees with {from_a}"))
        }
        (Some(s), _) | (None, Some(s)) => Ok(s),
        (None, None) => Err(format!(
            "{index_var} is set but not the number of shards{}: pass --shards N or set \
             {SHARDS_VAR}=N",
            if index_var == "JOB_COMPLETION_INDEX" {
                " (Kubernetes sets no count variable for an Indexed Job; N is its completions)"
            } else {
                " (SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MAX are missing)"
            }
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> + use<> {
        let vars: Vec<(String, String)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |name| vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone())
    }

    fn message(e: BatchError) -> String {
        e.to_string()
    }

    #[test]
    fn specs_parse_or_say_what_is_wrong() {
        assert_eq!(
            ShardSpec::parse("1/3").unwrap(),
            ShardSpec::Fixed(Shard { index: 1, count: 3 })
        );
        assert_eq!(ShardSpec::parse("auto").unwrap(), ShardSpec::Auto);
        let expected = |t: &str| {
            format!(
                "invalid --shard {t:?}: expected I/N (the 0-based index I of N shards, e.g. \
                 0/4) or auto"
            )
        };
        for t in ["a/b", "", "1", "1/", "/2", "-1/2", "1/2/3", "Auto", " 1/2"] {
            assert_eq!(
                message(ShardSpec::parse(t).unwrap_err()),
                expected(t),
                "{t:?}"
            );
        }
        assert_eq!(
            message(ShardSpec::parse("3/2").unwrap_err()),
            "invalid --shard \"3/2\": index 3 is not below the shard count 2 (shards are \
             numbered 0 to 1)"
        );
        assert_eq!(
            message(ShardSpec::parse("0/0").unwrap_err()),
            "invalid --shard \"0/0\": the shard count must be at least 1"
        );
    }

    #[test]
    fn slurm_and_kubernetes_variables_pick_the_shard() {
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]);
        assert_eq!(
            resolve_auto(&slurm, None).unwrap().0,
            Shard { index: 2, count: 3 }
        );
        // Only min and max (and an array numbered from 1).
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "4"),
        ]);
        assert_eq!(
            resolve_auto(&slurm, None).unwrap().0,
            Shard { index: 0, count: 4 }
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "1")]);
        assert_eq!(
            resolve_auto(&k8s, Some(2)).unwrap().0,
            Shard { index: 1, count: 2 }
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "1"), (SHARDS_VAR, "5")]);
        assert_eq!(
            resolve_auto(&k8s, None).unwrap().0,
            Shard { index: 1, count: 5 }
        );
        let e = message(resolve_auto(&env(&[("JOB_COMPLETION_INDEX", "1")]), None).unwrap_err());
        assert!(e.contains("pass --shards N or set RELUME_SHARDS=N"), "{e}");
        let e = message(resolve_auto(&env(&[]), None).unwrap_err());
        assert!(e.contains("neither SLURM_ARRAY_TASK_ID"), "{e}");
        let e = message(resolve_auto(&env(&[("JOB_COMPLETION_INDEX", "4")]), Some(4)).unwrap_err());
        assert!(e.contains("index 4 is not below the shard count 4"), "{e}");
        let disagree = env(&[
            ("SLURM_ARRAY_TASK_ID", "0"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]);
        let e = message(resolve_auto(&disagree, Some(4)).unwrap_err());
        assert!(
            e.contains("--shards 4 disagrees with SLURM_ARRAY_TASK_COUNT=3"),
            "{e}"
        );
    }

    #[test]
    fn shards_split_ids_exactly_once() {
        let ids: Vec<String> = (0..200).map(|i| format!("rec{i}__p__{i:08x}")).collect();
        for n in 1..6 {
            for id in &ids {
                let owners = (0..n).filter(|&i| Shard { index: i, count: n }.contains(id));
                assert_eq!(owners.count(), 1, "{id} of {n}");
            }
        }
    }
}
