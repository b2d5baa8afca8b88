//! The project's models served by a worker: `acps worker` plugs them into `acps-worker`.

use acps_shared::{Environment, EnvironmentSpec, Serves};
use acps_worker::EnvironmentFactory;
use std::collections::HashMap;

/// Builds environments with `acps_models::environment::build` and keeps them for later tasks:
/// it serves any spec of the project's models, and the worker checks that what it built is
/// the environment a task needs (this build may configure it differently from the learner's).
#[derive(Default)]
pub struct ModelFactory {
    cache: HashMap<EnvironmentSpec, Box<dyn Environment>>,
}

impl EnvironmentFactory for ModelFactory {
    fn serves(&self) -> Serves {
        Serves::Any
    }

    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, String> {
        if !self.cache.contains_key(spec) {
            let environment = acps_models::environment::build(spec).map_err(|e| e.to_string())?;
            self.cache.insert(*spec, environment);
        }
        Ok(self.cache.get_mut(spec).expect("inserted above").as_mut())
    }
}
