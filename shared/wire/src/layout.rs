//! The wire's layout as data: every payload's fields with their types, offsets, sizes and
//! alignments, the iceoryx2 type names, the capacities, the codes and the services' settings,
//! taken from the Rust definitions themselves. A worker in another language mirrors these; its
//! tests compare the mirror with [`describe`] (printed by `acps protocol`), so the two cannot
//! drift apart. docs/PROTOCOL.md explains what they mean.

use crate::ipc::{DEFAULT_QUEUE_DEPTH, LIMITS, MAX_ASKING_REQUESTS, MAX_IN_FLIGHT_PER_WORKER, MAX_WORKERS, RUN_ENV};
use crate::secret::{SECRET_BYTES, SECRET_ENV};
use crate::wire::{
    Answer, MAX_BATCH, MAX_CONTEXT, MAX_DIAGNOSTICS, MAX_SETTINGS_TEXT, MAX_THETA, PROTOCOL_VERSION, Refusal, Response,
    WireEnvironment, WireOutcome, WireTask, WorkerMessage,
};
use acps_shared::MAX_NAME;
use iceoryx2::prelude::ZeroCopySend;
use serde_json::{Value, json};
use std::mem::{align_of, offset_of, size_of};

/// One field: its name, its element type, how many elements (`None`: a scalar), where it lies.
struct Field {
    name: &'static str,
    element: &'static str,
    len: Option<usize>,
    offset: usize,
    size: usize,
    align: usize,
}

/// The size and alignment of the field `get` reads, without an instance's unsafe tricks.
fn measure<T, F>(_get: fn(&T) -> &F) -> (usize, usize) {
    (size_of::<F>(), align_of::<F>())
}

macro_rules! field {
    ($ty:ty, $field:ident, $element:expr) => {
        field!($ty, $field, $element, None)
    };
    ($ty:ty, $field:ident, $element:expr, $len:expr) => {{
        let (size, align) = measure(|value: &$ty| &value.$field);
        Field {
            name: stringify!($field),
            element: $element,
            len: $len,
            offset: offset_of!($ty, $field),
            size,
            align,
        }
    }};
}

/// A payload type: its short name, its iceoryx2 type name, size, alignment and fields.
fn payload<T: ZeroCopySend>(name: &str, fields: Vec<Field>) -> Value {
    // SAFETY: `type_name` only returns the name the type was registered under; the unsafety of
    // the trait concerns implementing it, not calling it.
    let type_name = unsafe { <T as ZeroCopySend>::type_name() };
    let fields: Vec<Value> = fields
        .into_iter()
        .map(|f| {
            json!({
                "name": f.name, "type": f.element, "len": f.len,
                "offset": f.offset, "size": f.size, "align": f.align,
            })
        })
        .collect();
    json!({
        "name": name, "type_name": type_name,
        "size": size_of::<T>(), "align": align_of::<T>(), "fields": fields,
    })
}

/// The wire's layout description, as JSON (see the module's documentation).
///
/// ```
/// let layout = acps_wire::layout::describe();
/// assert_eq!(layout["protocol"], acps_wire::wire::PROTOCOL_VERSION);
/// let task = layout["types"].as_array().unwrap().iter().find(|t| t["name"] == "WireTask").unwrap();
/// assert_eq!((task["type_name"].as_str(), task["size"].as_u64()), (Some("acps::WireTask"), Some(672)));
/// ```
pub fn describe() -> Value {
    let environment = payload::<WireEnvironment>(
        "WireEnvironment",
        vec![
            field!(WireEnvironment, name, "u8", Some(MAX_NAME)),
            field!(WireEnvironment, settings, "u64"),
            field!(WireEnvironment, parameters, "u64", Some(3)),
        ],
    );
    let task = payload::<WireTask>(
        "WireTask",
        vec![
            field!(WireTask, kind, "u32"),
            field!(WireTask, job, "u32"),
            field!(WireTask, context_len, "u32"),
            field!(WireTask, theta_len, "u32"),
            field!(WireTask, task_id, "u64"),
            field!(WireTask, seed, "u64"),
            field!(WireTask, environment, "WireEnvironment"),
            field!(WireTask, context, "f64", Some(MAX_CONTEXT)),
            field!(WireTask, theta, "f64", Some(MAX_THETA)),
        ],
    );
    let answer = payload::<Answer>(
        "Answer",
        vec![
            field!(Answer, response, "u32"),
            field!(Answer, protocol, "u32"),
            field!(Answer, run, "u64"),
            field!(Answer, refusal, "u32"),
            field!(Answer, environments, "u32"),
            field!(Answer, environment, "WireEnvironment"),
            field!(Answer, context_len, "u32"),
            field!(Answer, theta_len, "u32"),
            field!(Answer, settings_text_len, "u32"),
            field!(Answer, reserved, "u32"),
            field!(Answer, settings_text, "u8", Some(MAX_SETTINGS_TEXT)),
        ],
    );
    let outcome = payload::<WireOutcome>(
        "WireOutcome",
        vec![
            field!(WireOutcome, job, "u32"),
            field!(WireOutcome, ok, "u32"),
            field!(WireOutcome, task_id, "u64"),
            field!(WireOutcome, reward, "f64"),
            field!(WireOutcome, score, "f64"),
            field!(WireOutcome, diagnostics_len, "u32"),
            field!(WireOutcome, reserved, "u32"),
            field!(WireOutcome, diagnostics, "f64", Some(MAX_DIAGNOSTICS)),
        ],
    );
    let message = payload::<WorkerMessage>(
        "WorkerMessage",
        vec![
            field!(WorkerMessage, protocol, "u32"),
            field!(WorkerMessage, want, "u32"),
            field!(WorkerMessage, run, "u64"),
            field!(WorkerMessage, secret, "u8", Some(SECRET_BYTES)),
            field!(WorkerMessage, count, "u32"),
            field!(WorkerMessage, slowest_rollout_us, "u32"),
            field!(WorkerMessage, serves_one, "u32"),
            field!(WorkerMessage, context_len, "u32"),
            field!(WorkerMessage, theta_len, "u32"),
            field!(WorkerMessage, settings_text_len, "u32"),
            field!(WorkerMessage, environment, "WireEnvironment"),
            field!(WorkerMessage, settings_text, "u8", Some(MAX_SETTINGS_TEXT)),
            field!(WorkerMessage, outcomes, "WireOutcome", Some(MAX_BATCH)),
        ],
    );
    let limits = LIMITS;
    let event = json!({
        "max_listeners": limits.nodes, "max_notifiers": limits.nodes, "max_nodes": limits.nodes,
    });
    json!({
        "protocol": PROTOCOL_VERSION,
        "iceoryx2": "0.10.0",
        "limits": {
            "MAX_NAME": MAX_NAME, "MAX_CONTEXT": MAX_CONTEXT, "MAX_THETA": MAX_THETA,
            "MAX_DIAGNOSTICS": MAX_DIAGNOSTICS, "MAX_BATCH": MAX_BATCH,
            "MAX_SETTINGS_TEXT": MAX_SETTINGS_TEXT, "MAX_WORKERS": MAX_WORKERS,
            "MAX_IN_FLIGHT_PER_WORKER": MAX_IN_FLIGHT_PER_WORKER,
            "MAX_ASKING_REQUESTS": MAX_ASKING_REQUESTS, "DEFAULT_QUEUE_DEPTH": DEFAULT_QUEUE_DEPTH,
        },
        "codes": {
            "kind": {"train": 0, "evaluate": 1, "baseline": 2},
            "response": {
                "task": Response::Task as u32, "stop": Response::Stop as u32,
                "refused": Response::Refused as u32,
            },
            "refusal": {
                "protocol": Refusal::Protocol as u32, "run": Refusal::Run as u32,
                "environment": Refusal::Environment as u32, "sizes": Refusal::Sizes as u32,
                "secret": Refusal::Secret as u32,
            },
        },
        "types": [environment, task, answer, outcome, message],
        "services": {
            "run_env": RUN_ENV,
            "secret_env": SECRET_ENV,
            "secret_file": "/dev/shm/acps_{run}_secret",
            "prefix": "acps_{run}_",
            "root": "/tmp/acps-iceoryx2-{uid}/",
            "creation_timeout_ms": limits.creation_timeout.as_millis() as u64,
            "tasks": {
                "pattern": "request-response",
                "request": "WorkerMessage", "request_header": "()",
                "response": "[WireTask]", "response_header": "Answer",
                "max_servers": 1, "max_clients": MAX_WORKERS, "max_nodes": limits.nodes,
                "max_active_requests_per_client": limits.active_requests_per_client,
                "max_response_buffer_size": limits.response_buffer,
                "max_loaned_requests": limits.loaned_requests,
                "initial_max_slice_len": MAX_BATCH,
            },
            "to-learner": event.clone(),
            "to-workers": event,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_payload_is_described_without_gaps_or_overlaps() {
        let layout = describe();
        for ty in layout["types"].as_array().unwrap() {
            let mut end = 0;
            for field in ty["fields"].as_array().unwrap() {
                let offset = field["offset"].as_u64().unwrap();
                assert_eq!(
                    offset, end,
                    "{} has a gap or an overlap before {}",
                    ty["name"], field["name"]
                );
                end = offset + field["size"].as_u64().unwrap();
            }
            assert_eq!(end, ty["size"].as_u64().unwrap(), "{} ends with padding", ty["name"]);
            assert!(ty["type_name"].as_str().unwrap().starts_with("acps::"), "{ty}");
        }
    }

    #[test]
    fn the_secret_file_pattern_is_where_the_learner_writes() {
        let run = crate::ipc::RunName::new("x").unwrap();
        let pattern = describe()["services"]["secret_file"]
            .as_str()
            .unwrap()
            .replace("{run}", "x");
        assert_eq!(crate::secret::RunSecret::path(&run).to_str(), Some(pattern.as_str()));
    }

    #[test]
    fn the_root_pattern_is_where_the_nodes_are() {
        let pattern = describe()["services"]["root"]
            .as_str()
            .unwrap()
            .replace("{uid}", &crate::secret::current_user().to_string());
        assert_eq!(crate::ipc::iceoryx2_root().to_str(), Some(pattern.as_str()));
    }

    #[test]
    fn the_committed_description_is_current() {
        let committed = include_str!("../layout.json");
        let current = serde_json::to_string_pretty(&describe()).unwrap() + "\n";
        assert!(
            committed == current,
            "shared/wire/layout.json is stale: regenerate it with `cargo run -p acps -- protocol > shared/wire/layout.json`"
        );
    }
}
