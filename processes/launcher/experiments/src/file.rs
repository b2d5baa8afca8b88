//! Experiment files as read and written: [`LoadedFile`] reads one, knowing where each key
//! stands so that an error names its line; [`ExperimentFile::write_resolved`] writes the
//! resolved file of a run (`config.toml`), which re-runs it bit for bit.

use crate::keys::{ConfigError, Invalid, Problem};
use crate::regular::{Unread, read_regular};
use crate::settings::{ExperimentFile, key, keys};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The largest experiment or problem file read: 100,000 points (a grid's limit,
/// [`MAX_GRID_POINTS`](crate::problem_file::MAX_GRID_POINTS)) of 8 coordinates written in
/// full take about 16 MB of TOML. Parsing holds about 75 bytes per byte of a list of numbers,
/// so a file of 100 MB had taken gigabytes before any limit was checked.
pub const MAX_FILE_BYTES: u64 = 16 << 20;

/// The text of the regular file at `path`, of at most [`MAX_FILE_BYTES`].
fn read_text(path: &Path) -> std::io::Result<String> {
    read_regular(path, MAX_FILE_BYTES).map_err(|unread| match unread {
        Unread::Special(kind) => std::io::Error::other(format!("not a regular file but a {kind}")),
        Unread::TooLarge(bytes) => std::io::Error::other(format!(
            "{bytes} bytes, more than the {} MiB an experiment or problem file may have (100,000 \
             points of 8 coordinates): use a context grid (training_grid, test_grid) for more",
            MAX_FILE_BYTES >> 20
        )),
        Unread::Io(error) => error,
    })
}

/// Characters of a value an error shows before it is cut ([`shown_value`]).
pub const SHOWN_CHARS: usize = 120;

/// A value as written in a file or on the command line, for an error: its start and its length
/// when it is long (a list of a million points is not echoed whole).
///
/// ```
/// use acps_experiments::file::shown_value;
/// assert_eq!(shown_value("grid"), "grid");
/// assert!(shown_value(&"x".repeat(1000)).ends_with("x ... (1000 characters)"));
/// ```
pub fn shown_value(text: &str) -> String {
    match text.char_indices().nth(SHOWN_CHARS) {
        None => text.to_string(),
        Some((end, _)) => format!("{} ... ({} characters)", &text[..end], text.chars().count()),
    }
}

/// An experiment file as read: its values and where each top-level key stands.
pub struct LoadedFile {
    path: PathBuf,
    text: String,
    positions: BTreeMap<String, Position>,
    /// The file's values.
    pub values: ExperimentFile,
}

/// Where a top-level key and its value stand in a file.
struct Position {
    line: usize,
    value: Range<usize>,
}

impl LoadedFile {
    /// Read and parse an experiment file. Unknown keys, wrong types and malformed TOML are refused
    /// with the file and line; ranges are checked by [`crate::plan::Plan::new`].
    pub fn read(path: &Path) -> Result<Self, ConfigError> {
        let text = read_text(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(path, text)
    }

    /// Parse `text`; `path` names it in errors.
    pub fn parse(path: &Path, text: String) -> Result<Self, ConfigError> {
        let at = |span: Option<Range<usize>>, message: &str| {
            let line = span.map_or(String::new(), |s| format!("{}:", line_of(&text, s.start)));
            ConfigError::Syntax {
                message: format!("{}:{line} {message}", path.display()),
            }
        };
        let document = toml::de::DeTable::parse(&text).map_err(|e| {
            // toml says "duplicate key" and points at it: name it.
            let key = e.span().and_then(|span| text.get(span)).map(str::trim);
            match key {
                Some(key) if e.message() == "duplicate key" && !key.is_empty() => {
                    at(e.span(), &format!("duplicate key `{key}`: each key may be set once"))
                }
                _ => at(e.span(), e.message()),
            }
        })?;
        let mut positions = BTreeMap::new();
        collect_positions(document.get_ref(), "", &text, &mut positions);
        let values = match toml::from_str::<ExperimentFile>(&text) {
            Ok(values) => values,
            Err(error) => {
                // A wrong type or an unknown name inside a known key's value: say what the key
                // accepts. Unknown keys keep toml's message, which lists the known ones.
                let span = error.span();
                // The innermost key whose value holds the error.
                let owner = span.as_ref().and_then(|span| {
                    positions
                        .iter()
                        .filter(|(name, p)| {
                            p.value.start <= span.start
                                && span.end <= p.value.end
                                && keys().any(|k| k.name == name.as_str())
                        })
                        .min_by_key(|(_, p)| p.value.len())
                });
                return Err(match (owner, span) {
                    (Some((name, _)), Some(span)) => {
                        let key = key(name);
                        ConfigError::Syntax {
                            message: format!(
                                "{}:{}: {} must be {}, got {}",
                                path.display(),
                                line_of(&text, span.start),
                                key.name,
                                key.accepted,
                                &text[span]
                            ),
                        }
                    }
                    (_, span) => at(span, error.message()),
                });
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            text,
            positions,
            values,
        })
    }
}

/// Where every key of `table` stands, named `prefix` + key, and those of the tables inside it.
fn collect_positions(table: &toml::de::DeTable, prefix: &str, text: &str, positions: &mut BTreeMap<String, Position>) {
    for (key, value) in table.iter() {
        let name = format!("{prefix}{}", key.get_ref());
        if let toml::de::DeValue::Table(inner) = value.get_ref() {
            collect_positions(inner, &format!("{name}."), text, positions);
        }
        let position = Position {
            line: line_of(text, key.span().start),
            value: value.span(),
        };
        positions.insert(name, position);
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

impl ExperimentFile {
    /// The file's text: `header` (comment lines) and every set key. Fails on integers TOML cannot
    /// hold, which [`crate::plan::Plan::new`] refuses.
    pub fn to_toml(&self, header: &str) -> Result<String, ConfigError> {
        let body = toml::to_string(self)?;
        Ok(format!("{header}{body}"))
    }

    /// Write the resolved file of a run into its directory (`config.toml`).
    pub fn write_resolved(&self, dir: &Path) -> Result<(), ConfigError> {
        let path = dir.join("config.toml");
        let command = match self.problem {
            None => "acps experiment --config config.toml --out NEW_DIR",
            Some(_) => "acps run --config config.toml --worker-command CMD --out NEW_DIR",
        };
        let text = self.to_toml(&header("the run in this directory", command))?;
        std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::write(&path, text))
            .map_err(|e| cannot_write(&path, e))
    }

    /// Write the file to `path`, which must not exist yet: a hand-edited file is never replaced.
    pub fn save_new(&self, path: &Path) -> Result<(), ConfigError> {
        let command = match self.problem {
            None => "acps experiment --config FILE",
            Some(_) => "acps run --config FILE --worker-command CMD",
        };
        let text = self.to_toml(&header("an experiment", command))?;
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => ConfigError::Exists {
                    path: path.to_path_buf(),
                },
                _ => cannot_write(path, e),
            })?;
        std::io::Write::write_all(&mut file, text.as_bytes()).map_err(|e| cannot_write(path, e))
    }
}

fn cannot_write(path: &Path, source: std::io::Error) -> ConfigError {
    ConfigError::Write {
        path: path.to_path_buf(),
        source,
    }
}

/// The comment lines that open a written file: what it describes and how to run it.
fn header(what: &str, command: &str) -> String {
    format!(
        "# Every setting of {what}, written by acps {}.\n\
         # Run it with `{command}` (docs/EXPERIMENTS.md, \"Experiment files\").\n\n",
        env!("CARGO_PKG_VERSION")
    )
}

/// The message for `invalid`: the option when the value came from the command line, else the
/// file and line.
pub(crate) fn describe(invalid: Invalid, file: Option<&LoadedFile>, cli: &ExperimentFile) -> ConfigError {
    let key = key(invalid.key);
    let from_cli = cli.set_keys().iter().any(|k| k == key.name);
    let file = file.filter(|_| !from_cli);
    let position = file.and_then(|f| f.positions.get(key.name).map(|p| (f, p)));
    // A key that is not in the file (unset, or defaulted) is placed at its table's line.
    let table = file.and_then(|f| {
        let tables = std::iter::successors(key.name.rsplit_once('.'), |(table, _)| table.rsplit_once('.'));
        tables
            .filter_map(|(table, _)| f.positions.get(table))
            .map(|p| (f, p.line))
            .next()
    });
    let (subject, got) = match (from_cli, position, table, file) {
        (true, ..) => (key.flag(), None),
        (false, Some((f, p)), ..) => (
            format!("{}:{}: {}", f.path.display(), p.line, key.name),
            Some(shown_value(&f.text[p.value.clone()])),
        ),
        (false, None, Some((f, line)), _) => (format!("{}:{line}: {}", f.path.display(), key.name), None),
        (false, None, None, Some(f)) => (format!("{}: {}", f.path.display(), key.name), None),
        (false, None, None, None) => (key.name.to_string(), None),
    };
    let message = match invalid.problem {
        Problem::Range { got: value } => {
            format!("{subject} must be {}, got {}", key.accepted, got.unwrap_or(value))
        }
        Problem::Element { got } => format!("{subject} must be {}, got {got}", key.accepted),
        Problem::NotApplicable(kind) => {
            let applies: Vec<&str> = key.applies.iter().map(|k| k.name()).collect();
            format!(
                "{subject} applies to {} only, not to {}",
                applies.join(", "),
                kind.describe()
            )
        }
        Problem::Missing => format!("{subject} must be set: {}", key.accepted),
        Problem::Conflict(other) => {
            format!("{subject} and {other} exclude each other: give one of them")
        }
        Problem::NoMethod(methods) => {
            let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
            format!("{subject} applies only when methods lists {}", names.join(" or "))
        }
        Problem::OtherLearner { only, chosen } => format!(
            "{subject} is a setting of learner {} only, and the learner is {}",
            only.name(),
            chosen.name()
        ),
    };
    ConfigError::Invalid { key: key.name, message }
}

impl LoadedFile {
    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}
