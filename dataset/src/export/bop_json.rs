//! JSON as bop_toolkit's `inout.save_json` writes it (and BlenderProc's copy of it): a map of
//! numeric keys in their numeric order, one `  "key": value` line each, every value as Python's
//! `json.dumps(value, sort_keys=True)` prints it (`", "` and `": "` between items, keys sorted,
//! floats as Python's `repr`), and no newline after the closing brace.

use serde_json::Value;
use std::fmt::Write as _;

/// The file for `entries` (numeric key → value), in key order.
pub fn save_json(entries: &[(u64, Value)]) -> String {
    let mut sorted: Vec<&(u64, Value)> = entries.iter().collect();
    sorted.sort_by_key(|(k, _)| *k);
    let lines: Vec<String> = sorted.iter().map(|(k, v)| format!("  \"{k}\": {}", dumps(v))).collect();
    format!("{{\n{}\n}}", lines.join(",\n"))
}

/// Python's `json.dumps(value, sort_keys=True)`.
fn dumps(value: &Value) -> String {
    let mut out = String::new();
    write_value(&mut out, value);
    out
}

fn write_value(out: &mut String, value: &Value) {
    match value {
        Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
            (Some(u), _, _) => write!(out, "{u}").expect("strings take writes"),
            (_, Some(i), _) => write!(out, "{i}").expect("strings take writes"),
            (_, _, Some(f)) => out.push_str(&python_float(f)),
            _ => unreachable!("a JSON number is an integer or a float"),
        },
        Value::Array(items) => {
            out.push('[');
            for (k, item) in items.iter().enumerate() {
                if k > 0 {
                    out.push_str(", ");
                }
                write_value(out, item);
            }
            out.push(']');
        }
        // serde_json's map keeps its keys sorted, as sort_keys=True orders them.
        Value::Object(map) => {
            out.push('{');
            for (k, (key, item)) in map.iter().enumerate() {
                if k > 0 {
                    out.push_str(", ");
                }
                write!(out, "{}: ", Value::String(key.clone())).expect("strings take writes");
                write_value(out, item);
            }
            out.push('}');
        }
        other => out.push_str(&other.to_string()),
    }
}

/// A finite float as Python's `repr` writes it: the shortest digits that read back as the same
/// double; positional with at least one decimal from 1e-4 up to 1e16, else `d.ddde±XX`.
pub fn python_float(x: f64) -> String {
    // Rust's `{:e}` gives the same shortest digits: `-1.2345e-7`.
    let scientific = format!("{x:e}");
    let (mantissa, exponent) = scientific.split_once('e').expect("{:e} writes an exponent");
    let exponent: i32 = exponent.parse().expect("{:e} writes an integer exponent");
    let (sign, mantissa) = mantissa.strip_prefix('-').map_or(("", mantissa), |m| ("-", m));
    let digits: String = mantissa.chars().filter(|c| *c != '.').collect();
    if !(-4..16).contains(&exponent) {
        let sign_e = if exponent < 0 { '-' } else { '+' };
        return format!("{sign}{mantissa}e{sign_e}{:02}", exponent.abs());
    }
    if exponent < 0 {
        return format!("{sign}0.{}{digits}", "0".repeat((-exponent - 1) as usize));
    }
    let whole = exponent as usize + 1;
    if digits.len() <= whole {
        format!("{sign}{digits}{}.0", "0".repeat(whole - digits.len()))
    } else {
        format!("{sign}{}.{}", &digits[..whole], &digits[whole..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Every float reads back as itself, and takes Python's form: positional with a decimal
    /// point inside [1e-4, 1e16), an exponent with its sign and two digits or more outside.
    #[test]
    fn floats_read_back_exactly_in_pythons_layout() {
        let mut x = 1.234_567_890_123e-9_f64;
        while x < 1e20 {
            for v in [x, -x, x.round(), 1.0 / x] {
                let text = python_float(v);
                assert_eq!(text.parse::<f64>().unwrap(), v, "{text}");
                let positional = v == 0.0 || (1e-4..1e16).contains(&v.abs());
                assert_eq!(text.contains('e'), !positional, "{v}: {text}");
                if positional {
                    assert!(text.contains('.') && !text.ends_with('.'), "{text}");
                } else {
                    let exponent = text.split_once('e').unwrap().1;
                    assert!(exponent.starts_with(['+', '-']) && exponent.len() >= 3, "{text}");
                }
            }
            x *= 7.3;
        }
        assert!(!python_float(0.1).contains("00000"), "the shortest digits");
    }

    #[test]
    fn files_list_numeric_keys_in_numeric_order_one_line_each() {
        let text = save_json(&[(10, json!({"b": [1, 2.5], "a": -3})), (2, json!([]))]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(lines[1].starts_with("  \"2\": ") && lines[2].starts_with("  \"10\": "), "{text}");
        assert!(lines[2].find("\"a\"").unwrap() < lines[2].find("\"b\"").unwrap(), "keys sorted");
        assert!(text.ends_with('}') && lines[1].ends_with(','), "{text}");
        let back: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(back["10"], json!({"a": -3, "b": [1, 2.5]}));
    }
}
