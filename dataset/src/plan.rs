//! Which image is which: global indices, per-image seeds and choices, shards, and file names.
//! Everything here depends on the settings and the global index only, never on the batch size,
//! the shard count, the thread count or what an earlier run got through.

use crate::error::{Error, Result};
use vkdiff_setting::Message;

/// splitmix64's finaliser: a bijection of u64 that scatters nearby inputs (prompt templates
/// draw their choices from the same generator, on a stream of their own).
pub(crate) fn mix(x: u64) -> u64 {
    vkdiff_pipeline::splitmix64(x)
}

/// Image `index`'s seed: `(splitmix64(seed) + index) mod 2³²`. Consecutive within a dataset,
/// so no two of its first 2³² images share noise, and unrelated between datasets of nearby
/// seeds. 32 bits because `torch.Generator.manual_seed` feeds only those to its engine.
pub fn image_seed(dataset_seed: u64, index: u64) -> u64 {
    mix(dataset_seed).wrapping_add(index) & 0xFFFF_FFFF
}

/// The seed of an image regenerated `round` times (`--regenerate-flagged`): its first seed
/// where it never was, else one drawn from the first seed and the round.
pub fn resampled_seed(seed: u64, round: u64) -> u64 {
    if round == 0 {
        seed
    } else {
        mix(seed ^ round.rotate_left(32)) & 0xFFFF_FFFF
    }
}

/// What a per-image choice is for; each draws from its own stream of the image seed.
#[derive(Clone, Copy)]
pub enum Choice {
    Prompt = 1,
    StyleSet = 2,
}

/// Which of `n` options the image with `seed` takes for `what`.
pub fn choose(seed: u64, what: Choice, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    (mix(seed ^ ((what as u64) << 56)) % n as u64) as usize
}

/// A part of the scenes: those whose index is `index` mod `count`, with all their images. The
/// unit is the scene so that no scene is rendered twice, and it is strided so that shards get
/// the same mix of work and finish together.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u64,
    pub count: u64,
}

impl Shard {
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    pub fn owns_scene(&self, scene: u64) -> bool {
        scene % self.count == self.index
    }

    /// `I/N`, 0-based as Slurm and Kubernetes number.
    pub fn parse(text: &str) -> Result<Shard> {
        let bad = || {
            Error::Setting(
                Message::setting("shard").then(format!(" {text}: expected I/N with 0 <= I < N (0-based, e.g. 0/4)")),
            )
        };
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let (index, count) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        Shard::new(index, count).map_err(|_| bad())
    }

    fn new(index: u64, count: u64) -> Result<Shard> {
        if count == 0 || index >= count {
            return Err(Error::Config(format!("shard {index}/{count}: needs 0 <= index < count")));
        }
        Ok(Shard { index, count })
    }

    /// The shard of this process: `--shard I/N`; else a Slurm array task
    /// (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN` of `SLURM_ARRAY_TASK_COUNT`); else a
    /// Kubernetes Indexed Job's `JOB_COMPLETION_INDEX` of `--shards N`; else the whole set.
    /// Returns where it came from, for the log.
    pub fn resolve(
        flag: Option<&str>,
        shards: Option<u64>,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<(Shard, String)> {
        if let Some(text) = flag {
            if shards.is_some() {
                return Err(Error::Setting(
                    Message::text("give ")
                        .and("shard")
                        .then(" I/N or ")
                        .and("shards")
                        .then(" N (with JOB_COMPLETION_INDEX), not both"),
                ));
            }
            return Ok((Shard::parse(text)?, Message::setting("shard").to_string()));
        }
        let number = |name: &str| -> Result<Option<u64>> {
            env(name)
                .map(|v| {
                    v.trim().parse::<u64>().map_err(|_| Error::Config(format!("{name}={v} is not a whole number")))
                })
                .transpose()
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            let (min, count) =
                match (number("SLURM_ARRAY_TASK_MIN")?, number("SLURM_ARRAY_TASK_COUNT")?) {
                    (Some(min), Some(count)) => (min, count),
                    _ => return Err(Error::Setting(
                        Message::text(
                            "SLURM_ARRAY_TASK_ID is set without SLURM_ARRAY_TASK_MIN and SLURM_ARRAY_TASK_COUNT; give ",
                        )
                        .and("shard")
                        .then(" I/N"),
                    )),
                };
            if number("SLURM_ARRAY_TASK_STEP")?.is_some_and(|step| step != 1) || id < min || id - min >= count {
                return Err(Error::Setting(
                    Message::text(format!(
                        "Slurm array task {id} (min {min}, count {count}) is not in a contiguous array: submit \
                        --array=0-{} (no step), or give ",
                        count.saturating_sub(1)
                    ))
                    .and("shard")
                    .then(" I/N"),
                ));
            }
            if shards.is_some_and(|n| n != count) {
                return Err(Error::Setting(
                    Message::setting("shards")
                        .then(format!(" {} disagrees with SLURM_ARRAY_TASK_COUNT={count}", shards.unwrap_or(0))),
                ));
            }
            return Ok((Shard::new(id - min, count)?, format!("Slurm array task {id}")));
        }
        match (number("JOB_COMPLETION_INDEX")?, shards) {
            (Some(index), Some(count)) => {
                let shard = Shard::new(index, count).map_err(|_| {
                    Error::Setting(
                        Message::text(format!("JOB_COMPLETION_INDEX={index} is not below "))
                            .and("shards")
                            .then(format!(" {count}")),
                    )
                })?;
                Ok((shard, format!("JOB_COMPLETION_INDEX={index}")))
            }
            (Some(_), None) => Err(Error::Setting(
                Message::text("JOB_COMPLETION_INDEX is set: give ").and("shards").then(" N, the Job's completions"),
            )),
            (None, Some(_)) => Err(Error::Setting(
                Message::setting("shards")
                    .then(" N needs JOB_COMPLETION_INDEX (a Kubernetes Indexed Job); elsewhere give ")
                    .and("shard")
                    .then(" I/N"),
            )),
            (None, None) => Ok((Shard::ALL, "the whole set".into())),
        }
    }
}

/// The files of one image, relative to the dataset folder.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageFiles {
    pub image: String,
    pub depth: String,
    pub control: String,
    pub mask: String,
    /// img2img's start, the scene's shaded render (`--init-strength`).
    pub init: String,
    pub record: String,
}

/// The folders, one kind of file each (`init` stays empty without `--init-strength`).
pub const FOLDERS: [&str; 6] = ["images", "depth", "control", "masks", "init", "records"];

impl ImageFiles {
    /// Image `index` of a dataset of `total` images: zero-padded to 6 digits, or more when the
    /// set needs them, so names sort in index order.
    pub fn new(index: u64, total: u64) -> ImageFiles {
        let digits = total.saturating_sub(1).to_string().len().max(6);
        let stem = format!("{index:0digits$}");
        ImageFiles {
            image: format!("images/{stem}.png"),
            depth: format!("depth/{stem}.exr"),
            control: format!("control/{stem}.png"),
            mask: format!("masks/{stem}.png"),
            init: format!("init/{stem}.png"),
            record: format!("records/{stem}.json"),
        }
    }

    /// The files every image is made of, written in this order (the record last: it marks the
    /// image done); img2img images add their init image.
    pub fn outputs(&self) -> [&str; 4] {
        [&self.depth, &self.control, &self.mask, &self.image]
    }
}

/// The index in a file name `NNNNNN.ext` or its temporary `.NNNNNN.ext.partial-PID`.
pub fn index_of(name: &str) -> Option<u64> {
    name.trim_start_matches('.').split('.').next()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn env(vars: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let map: HashMap<String, String> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        move |k| map.get(k).cloned()
    }

    #[test]
    fn seeds_are_distinct_and_depend_on_the_dataset_seed_and_index_only() {
        let seeds: std::collections::HashSet<u64> = (0..10_000).map(|i| image_seed(7, i)).collect();
        assert_eq!(seeds.len(), 10_000);
        assert!(seeds.iter().all(|&s| s < 1 << 32));
        assert_ne!(image_seed(7, 0), image_seed(8, 0));
        assert_ne!(image_seed(7, 1), image_seed(8, 0), "nearby dataset seeds do not share images' noise");
        let picks: Vec<usize> = (0..1000).map(|i| choose(image_seed(0, i), Choice::Prompt, 3)).collect();
        assert!((0..3).all(|k| picks.iter().filter(|&&p| p == k).count() > 250), "choices spread over the options");
    }

    #[test]
    fn shards_partition_the_scenes() {
        let shards: Vec<Shard> = (0..3).map(|i| Shard::parse(&format!("{i}/3")).unwrap()).collect();
        for scene in 0..100 {
            assert_eq!(shards.iter().filter(|s| s.owns_scene(scene)).count(), 1);
        }
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2"] {
            assert!(Shard::parse(bad).unwrap_err().to_string().contains("shard"), "{bad}");
        }
    }

    #[test]
    fn the_shard_comes_from_the_flag_slurm_or_kubernetes() {
        let none = env(&[]);
        assert_eq!(Shard::resolve(None, None, &none).unwrap().0, Shard::ALL);
        assert_eq!(Shard::resolve(Some("1/4"), None, &none).unwrap().0, Shard { index: 1, count: 4 });
        let slurm =
            env(&[("SLURM_ARRAY_TASK_ID", "12"), ("SLURM_ARRAY_TASK_MIN", "10"), ("SLURM_ARRAY_TASK_COUNT", "4")]);
        assert_eq!(Shard::resolve(None, None, &slurm).unwrap().0, Shard { index: 2, count: 4 });
        assert_eq!(Shard::resolve(Some("0/2"), None, &slurm).unwrap().0, Shard { index: 0, count: 2 }, "the flag wins");
        let stepped = env(&[
            ("SLURM_ARRAY_TASK_ID", "6"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ]);
        assert!(Shard::resolve(None, None, &stepped).unwrap_err().to_string().contains("contiguous"));
        let partial = env(&[("SLURM_ARRAY_TASK_ID", "1")]);
        assert!(Shard::resolve(None, None, &partial).unwrap_err().to_string().contains("SLURM_ARRAY_TASK_MIN"));
        let k8s = env(&[("JOB_COMPLETION_INDEX", "3")]);
        assert_eq!(Shard::resolve(None, Some(5), &k8s).unwrap().0, Shard { index: 3, count: 5 });
        assert!(Shard::resolve(None, None, &k8s).unwrap_err().to_string().contains("shards"));
        assert!(Shard::resolve(None, Some(3), &k8s).unwrap_err().to_string().contains("not below shards 3"));
        assert!(Shard::resolve(None, Some(3), &none).unwrap_err().to_string().contains("JOB_COMPLETION_INDEX"));
        assert!(Shard::resolve(None, None, &env(&[("JOB_COMPLETION_INDEX", "x")]))
            .unwrap_err()
            .to_string()
            .contains("not a whole number"));
    }

    #[test]
    fn names_sort_in_index_order() {
        assert_eq!(ImageFiles::new(42, 6000).image, "images/000042.png");
        assert_eq!(ImageFiles::new(42, 12_000_000).record, "records/00000042.json");
        assert_eq!(index_of("000042.png"), Some(42));
        assert_eq!(index_of(".000042.png.partial-77"), Some(42));
        assert_eq!(index_of(".dataset.json.partial-77"), None);
    }
}
