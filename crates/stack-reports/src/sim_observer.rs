//! What `crs sim` runs next to the stack ([`RunObserver`]): the operator console while the run
//! lasts (`--console ADDR`) and the run's report (`<out>/index.html` + its plots, [`run_plots`]).

use crate::run_plots::{self, RunRecord};
use crs_ipc::{JointSetpoint, LoopStatsSample, PlantTruth, StateEvent};
use sim_runs::console_setup::console_config;
use sim_runs::sim_run::{RunObserver, RunStart, Summary};
use std::net::SocketAddr;
use std::path::Path;

/// The console's address and, off loopback, its token.
#[derive(Clone, Debug)]
pub struct ConsoleRequest {
    pub addr: SocketAddr,
    pub token: Option<String>,
}

/// The console (when asked for) and the plots of one run. Dropping it stops the console.
pub struct SimObserver {
    console_request: Option<ConsoleRequest>,
    console: Option<crs_console::ConsoleHandle>,
    plots: Option<RunRecord>,
}

impl SimObserver {
    pub fn new(console: Option<ConsoleRequest>) -> Self {
        Self {
            console_request: console,
            console: None,
            plots: None,
        }
    }

    /// Stops the console (if one runs).
    pub fn stop_console(&mut self) {
        drop(self.console.take());
    }
}

impl RunObserver for SimObserver {
    fn started(&mut self, run: &RunStart<'_>) -> Result<(), sim_runs::sim_run::ObserverError> {
        if let Some(req) = &self.console_request {
            let mut cfg = console_config(
                req.addr,
                req.token.clone(),
                run.prefix,
                run.daemon,
                run.platform,
                run.waypoints,
            );
            // The START RIDE button when the ride waits for an operator.
            if let Some(sock) = run.control {
                cfg.rides = sim_runs::console_setup::ride_setup(
                    run.daemon,
                    run.platform,
                    Some(sock.to_path_buf()),
                    run.waypoints,
                )?;
            }
            let h = crs_console::spawn(cfg)?;
            println!("  operator console: http://{}/", h.addr);
            self.console = Some(h);
        }
        let p = run.platform.model.params();
        self.plots = Some(RunRecord::new(p.f_min, p.f_max));
        Ok(())
    }
    fn setpoint(&mut self, sp: &JointSetpoint) {
        if let Some(p) = self.plots.as_mut() {
            p.setpoint(sp);
        }
    }
    fn truth(&mut self, t: &PlantTruth) {
        if let Some(p) = self.plots.as_mut() {
            p.truth(t);
        }
    }
    fn loop_stats(&mut self, s: &LoopStatsSample) {
        if let Some(p) = self.plots.as_mut() {
            p.loop_stats(s);
        }
    }
    fn event(&mut self, e: &StateEvent) {
        if let Some(p) = self.plots.as_mut() {
            p.event(e);
        }
    }
    fn finished(&mut self, out: &Path, summary: &Summary) {
        let Some(plots) = self.plots.as_ref() else {
            return;
        };
        match run_plots::write(out, plots, summary) {
            Ok(index) => println!("plots written to {}", index.display()),
            Err(e) => println!("plots NOT written: {e}"),
        }
    }
}
