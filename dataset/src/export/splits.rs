//! Train/val/test splits that keep each scene's crops together (crops of one scene overlap, so
//! splitting them leaks) and that do not move when the set grows: a scene's split is a function
//! of the export seed and the scene's seed alone.

use crate::error::{Error, Result};
use crate::plan::mix;
use vkdiff_setting::Message;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Split {
    Train,
    Val,
    Test,
}

impl Split {
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    /// The name YOLO, COCO and WebDataset users give it.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }
}

/// The shares of scenes that go to val and test; train takes the rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitFractions {
    pub val: f64,
    pub test: f64,
    pub seed: u64,
}

impl SplitFractions {
    /// Each fraction in [0, 1), and train left with something.
    pub fn check(&self) -> Result<()> {
        for (name, f) in [("val_fraction", self.val), ("test_fraction", self.test)] {
            if !(0.0..1.0).contains(&f) {
                return Err(Error::Setting(Message::setting(name).then(format!(" {f} must lie in [0, 1)"))));
            }
        }
        if self.val + self.test >= 1.0 {
            return Err(Error::Setting(
                Message::setting("val_fraction")
                    .then(format!(" {} and ", self.val))
                    .and("test_fraction")
                    .then(format!(" {} leave nothing to train on: their sum must be below 1", self.test)),
            ));
        }
        Ok(())
    }

    /// The split of the scene with seed `scene_seed`: a uniform draw in [0, 1) from the two
    /// seeds, test below `test`, val below `test + val`. A scene's draw never changes, so adding
    /// scenes moves none, and raising a fraction only moves scenes into that split.
    pub fn of_scene(&self, scene_seed: u64) -> Split {
        let u = self.draw(scene_seed);
        if u < self.test {
            Split::Test
        } else if u < self.test + self.val {
            Split::Val
        } else {
            Split::Train
        }
    }
}

impl SplitFractions {
    /// The scene's uniform draw in [0, 1).
    fn draw(&self, scene_seed: u64) -> f64 {
        (mix(self.seed ^ mix(scene_seed)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The split of each of `scenes` (distinct seeds). As [`Self::of_scene`], except that a
    /// split asked for (fraction above 0) that no scene's draw falls in takes the train scene
    /// whose draw lies nearest its range, while train keeps one: trainers refuse an empty
    /// validation set. Only sets too small for their fractions are touched, and there a scene
    /// may move as the set grows.
    pub fn of_scenes(&self, scenes: &[u64]) -> Vec<Split> {
        let mut splits: Vec<Split> = scenes.iter().map(|&s| self.of_scene(s)).collect();
        for (split, low, high) in [(Split::Val, self.test, self.test + self.val), (Split::Test, 0.0, self.test)] {
            let train = splits.iter().filter(|s| **s == Split::Train).count();
            if high <= low || splits.contains(&split) || train < 2 {
                continue;
            }
            let distance = |k: usize| {
                let u = self.draw(scenes[k]);
                (low - u).max(u - high).max(0.0)
            };
            let nearest = (0..scenes.len())
                .filter(|&k| splits[k] == Split::Train)
                .min_by(|&a, &b| distance(a).total_cmp(&distance(b)))
                .expect("train has scenes");
            splits[nearest] = split;
        }
        splits
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_follow_the_fractions_and_stay_put_as_the_set_grows() {
        let f = SplitFractions { val: 0.2, test: 0.1, seed: 3 };
        let splits: Vec<Split> = (0..10_000).map(|s| f.of_scene(1000 + s)).collect();
        let share = |split| splits.iter().filter(|&&s| s == split).count() as f64 / 10_000.0;
        assert!((share(Split::Val) - 0.2).abs() < 0.02 && (share(Split::Test) - 0.1).abs() < 0.02);
        // Growing the set is asking about more scenes: the first ones' answers are unchanged.
        assert!((0..100).all(|s| f.of_scene(1000 + s) == splits[s as usize]));
        assert_ne!(splits, (0..10_000).map(|s| SplitFractions { seed: 4, ..f }.of_scene(1000 + s)).collect::<Vec<_>>());
    }

    #[test]
    fn a_small_set_still_gets_a_scene_in_every_split_asked_for() {
        let f = SplitFractions { val: 0.1, test: 0.1, seed: 0 };
        let scenes: Vec<u64> = (5..8).collect();
        let splits = f.of_scenes(&scenes);
        assert!(Split::ALL.iter().all(|s| splits.contains(s)), "{splits:?}");
        assert_eq!(f.of_scenes(&[5]), vec![Split::Train], "train keeps the only scene");
        let big: Vec<u64> = (0..1000).collect();
        let drawn: Vec<Split> = big.iter().map(|&s| f.of_scene(s)).collect();
        assert_eq!(f.of_scenes(&big), drawn, "a set large enough keeps every scene's draw");
    }

    #[test]
    fn fractions_outside_the_unit_interval_or_leaving_no_train_are_refused() {
        for (val, test) in [(-0.1, 0.0), (1.0, 0.0), (0.0, 1.5), (0.6, 0.4), (f64::NAN, 0.0)] {
            assert!(SplitFractions { val, test, seed: 0 }.check().is_err(), "{val} {test}");
        }
        assert!(SplitFractions { val: 0.0, test: 0.0, seed: 0 }.check().is_ok());
    }
}
