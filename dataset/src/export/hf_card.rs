//! The Hugging Face export's README.md: a dataset card whose `configs` name the splits' folders
//! and the features of every column, so that `datasets.load_dataset(OUT)` (and the Hub, once
//! pushed) gives `objects.category` as a `ClassLabel` with the categories' names. The features
//! are inferred from the metadata rows as `datasets` would infer them, and written in the YAML
//! `Features._to_yaml_list` writes.

use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// A column's feature.
#[derive(Clone, Debug, PartialEq)]
enum Feature {
    Null,
    Bool,
    Int,
    Float,
    Str,
    Image,
    Labels(Vec<String>),
    List(Box<Feature>),
    Struct(BTreeMap<String, Feature>),
}

impl Feature {
    /// The feature of a JSON value.
    fn of(v: &Value) -> Feature {
        match v {
            Value::Null => Feature::Null,
            Value::Bool(_) => Feature::Bool,
            Value::Number(n) if n.is_f64() => Feature::Float,
            Value::Number(_) => Feature::Int,
            Value::String(_) => Feature::Str,
            Value::Array(items) => {
                Feature::List(Box::new(items.iter().map(Feature::of).fold(Feature::Null, Feature::merge)))
            }
            Value::Object(map) => Feature::Struct(map.iter().map(|(k, v)| (k.clone(), Feature::of(v))).collect()),
        }
    }

    /// The feature that holds both: nulls take the other's, integers widen to floats, structs
    /// take every field; anything else becomes a string.
    fn merge(self, other: Feature) -> Feature {
        use Feature::*;
        match (self, other) {
            (Null, x) | (x, Null) => x,
            (Int, Float) | (Float, Int) => Float,
            (List(a), List(b)) => List(Box::new(a.merge(*b))),
            (Struct(mut a), Struct(b)) => {
                for (k, f) in b {
                    let merged = a.remove(&k).map_or(f.clone(), |g| g.merge(f));
                    a.insert(k, merged);
                }
                Struct(a)
            }
            (a, b) if a == b => a,
            _ => Str,
        }
    }

    /// The YAML of this feature under a field `name` (or `list:`), at `indent` spaces.
    fn yaml(&self, out: &mut String, indent: usize) {
        let pad = " ".repeat(indent);
        match self {
            Feature::Null => {
                let _ = writeln!(out, "{pad}dtype: 'null'");
            }
            Feature::Bool | Feature::Int | Feature::Float | Feature::Str | Feature::Image => {
                let _ = writeln!(out, "{pad}dtype: {}", self.scalar());
            }
            Feature::Labels(names) => {
                let _ = writeln!(out, "{pad}dtype:");
                labels(out, names, indent + 2);
            }
            Feature::List(inner) => match &**inner {
                Feature::Struct(fields) => {
                    let _ = writeln!(out, "{pad}list:");
                    struct_fields(out, fields, indent);
                }
                Feature::Labels(names) => {
                    let _ = writeln!(out, "{pad}list:");
                    labels(out, names, indent + 2);
                }
                Feature::List(_) => {
                    let _ = writeln!(out, "{pad}list:");
                    inner.yaml(out, indent + 2);
                }
                scalar => {
                    let _ = writeln!(out, "{pad}list: {}", scalar.scalar());
                }
            },
            Feature::Struct(fields) => {
                let _ = writeln!(out, "{pad}struct:");
                struct_fields(out, fields, indent);
            }
        }
    }

    fn scalar(&self) -> &'static str {
        match self {
            Feature::Bool => "bool",
            Feature::Int => "int64",
            Feature::Float => "float64",
            Feature::Image => "image",
            Feature::Null => "'null'",
            _ => "string",
        }
    }
}

fn labels(out: &mut String, names: &[String], indent: usize) {
    let pad = " ".repeat(indent);
    let _ = writeln!(out, "{pad}class_label:\n{pad}  names:");
    for (k, name) in names.iter().enumerate() {
        let _ = writeln!(out, "{pad}    '{k}': {}", serde_json::to_string(name).expect("strings serialise"));
    }
}

fn struct_fields(out: &mut String, fields: &BTreeMap<String, Feature>, indent: usize) {
    let pad = " ".repeat(indent);
    for (name, f) in fields {
        let _ = writeln!(out, "{pad}- name: {name}");
        f.yaml(out, indent + 2);
    }
}

/// The card for metadata `rows` of the splits `splits` (folder names), whose
/// `objects.category` indexes `names`.
pub fn card(rows: &[Value], splits: &[&str], names: &[String]) -> String {
    let mut columns = rows.iter().map(Feature::of).fold(Feature::Struct(BTreeMap::new()), Feature::merge);
    let Feature::Struct(fields) = &mut columns else { unreachable!("rows are objects") };
    // imagefolder's columns: `file_name` is the image, `mask_file_name` the second image `mask`.
    for (file, column) in [("file_name", "image"), ("mask_file_name", "mask")] {
        if fields.remove(file).is_some() {
            fields.insert(column.into(), Feature::Image);
        }
    }
    if let Some(Feature::Struct(objects)) = fields.get_mut("objects") {
        objects.insert("category".into(), Feature::List(Box::new(Feature::Labels(names.to_vec()))));
    }
    let mut out = String::from("---\nconfigs:\n- config_name: default\n  data_files:\n");
    for split in splits {
        let _ = writeln!(out, "  - split: {split}\n    path: {split}/**");
    }
    out.push_str("  features:\n");
    struct_fields(&mut out, fields, 2);
    out.push_str(
        "---\n\nInstance segmentation exported by vkdiff: `datasets.load_dataset(\"PATH\")` loads it with\n\
         `objects.category` as a ClassLabel of the categories' names; `mask` is each image's 16-bit instance\n\
         mask, `objects.mask_id` each instance's value in it.\n",
    );
    out
}
