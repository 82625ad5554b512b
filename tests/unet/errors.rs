//! Broken checkpoints and inputs: one error naming what is wrong.
