//! Every physical parameter by its [`Param`] name, the friction coefficients included: one
//! getter and one all-or-nothing setter over [`Params`], the obstacles and the self-collision
//! set, so a name means the same thing to `params()`, `set_params` and the gradients.

use super::Simulator;
use crate::error::{Error, Result};
use crate::params::{check_mu, validate_params, Param, ParamValue};
use std::sync::Arc;

impl Simulator {
    /// A parameter's current value; `None` for `mu_self` in a scene without self-collision.
    pub fn param(&self, p: Param) -> Option<ParamValue> {
        match p {
            Param::MuObstacles => Some(ParamValue::List(
                self.model.obstacles.iter().map(|o| o.mu).collect(),
            )),
            Param::MuSelf => self
                .model
                .self_collision
                .as_ref()
                .map(|sc| ParamValue::Scalar(sc.mu)),
            _ => self.model.params.get(p),
        }
    }

    /// Sets parameters by name. Everything is validated before anything changes: on error
    /// (a wrong kind or length, a bad value, `mu_self` without self-collision) nothing does.
    /// Refactors once if h, density or a stiffness changed.
    pub fn set_param_values(&mut self, values: &[(Param, ParamValue)]) -> Result<()> {
        let mut params = self.model.params.clone();
        let mut mu_obstacles = None;
        let mut mu_self = None;
        for (p, value) in values {
            match (p, value) {
                (Param::MuObstacles, ParamValue::List(mus)) => {
                    let count = self.model.obstacles.len();
                    if mus.len() != count {
                        return Err(Error::Param(format!(
                            "mu_obstacles must have one number per obstacle ({count}), got {}",
                            mus.len()
                        )));
                    }
                    for (i, &mu) in mus.iter().enumerate() {
                        check_mu(&format!("mu_obstacles[{i}]"), mu, Error::Param)?;
                    }
                    mu_obstacles = Some(mus.clone());
                }
                (Param::MuSelf, ParamValue::Scalar(mu)) => {
                    if self.model.self_collision.is_none() {
                        return Err(Error::Param(
                            "mu_self: the scene has no self-collision".into(),
                        ));
                    }
                    check_mu("mu_self", *mu, Error::Param)?;
                    mu_self = Some(*mu);
                }
                (Param::MuObstacles | Param::MuSelf, _) => {
                    return Err(Error::Param(format!(
                        "{} must be {}",
                        p.name(),
                        p.kind().what()
                    )))
                }
                _ => params.set(*p, value.clone())?,
            }
        }
        validate_params(&params)?;
        // The only step that can still fail (a refactorization) changes nothing when it does.
        self.set_params(params)?;
        // Unchanged values leave the model shared (a tape recorded with it stays valid).
        let current_obstacles: Vec<f64> = self.model.obstacles.iter().map(|o| o.mu).collect();
        let mu_obstacles = mu_obstacles.filter(|m| *m != current_obstacles);
        let current_self = self.model.self_collision.as_ref().map(|sc| sc.mu);
        let mu_self = mu_self.filter(|&m| Some(m) != current_self);
        if mu_obstacles.is_some() || mu_self.is_some() {
            let model = Arc::make_mut(&mut self.model);
            if let Some(mus) = mu_obstacles {
                for (o, mu) in model.obstacles.iter_mut().zip(mus) {
                    o.mu = mu;
                }
            }
            if let (Some(mu), Some(sc)) = (mu_self, model.self_collision.as_mut()) {
                sc.mu = mu;
            }
        }
        Ok(())
    }
}
