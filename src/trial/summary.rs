//! What a trial's run says when it ends: the lines the command line prints.

use super::dressing::{DressingReport, Grip, Hand, Side};
use super::{Fit, Trial, TrialOutcome, WRENCH_MEAN_S};

impl TrialOutcome {
    /// The run's figures as lines of text: its course and cost, the force
    /// and pressure on the body, the ease at each girth; for a dressing its
    /// progress and forces.
    pub fn summary(&self, t: &Trial) -> Vec<String> {
        match &self.fit.dressing {
            Some(report) => dressing_summary(t, &self.fit, report),
            None => fit_summary(t, &self.fit),
        }
    }

    /// What the run warns of (stderr): the fit's warnings, its outcome, a
    /// run stopped before its end.
    pub fn warnings(&self) -> Vec<String> {
        let mut w: Vec<String> = self
            .fit
            .warnings
            .iter()
            .map(|w| format!("warning: {w}"))
            .collect();
        w.extend(self.fit.outcome.as_ref().map(|o| o.line()));
        if let (Some(r), Some(d)) = (&self.fit.dressing, &self.dressing) {
            let run = &d.dressing;
            let way = 100.0 * (self.sim.time - run.t_move).max(0.0) / (run.t_end - run.t_move);
            let steps = d.rows.len();
            if r.stopped_early {
                w.push(format!(
                    "stopped by a signal at t = {:.4} s, {way:.0} % of the way through the \
                     dressing: the outputs hold the {steps} steps taken",
                    self.sim.time
                ));
            }
            if let Some(l) = r.time_limit_s {
                w.push(format!(
                    "the dressing was cut short {l} s after sewing (--max-time), {way:.0} % of \
                     the way: the outputs hold the {steps} steps taken"
                ));
            }
        }
        w
    }
}

fn fit_summary(t: &Trial, fit: &Fit) -> Vec<String> {
    let mut out = Vec::new();
    let r = &fit.run;
    out.push(format!(
        "{}: sewn in {:.2} s, {}; {} steps, {:.1} s wall ({:.1} ms/step: assemble {:.1}, solve {:.1} ({:.1} iterations), contacts {:.1})",
        t.garment.name,
        r.sewing_s,
        match r.settle_time_s {
            Some(s) => format!("settled {s:.2} s after sewing"),
            None => format!("NOT settled (rms speed {:.4} m/s)", r.final_rms_speed_m_s),
        },
        r.steps,
        r.wall_s,
        r.ms_per_step,
        r.time_split_ms_per_step.assemble,
        r.time_split_ms_per_step.solve,
        r.mean_solver_iterations,
        r.time_split_ms_per_step.collide
    ));
    if let (Some(m), Some(play)) = (&r.motion, r.motion_s) {
        let c = &m.time_split_ms_per_step;
        out.push(format!(
            "the body's motion: {} steps, {:.1} s wall for {:.2} s (real-time factor {:.2}; {:.1} ms/step: \
             assemble {:.1}, solve {:.1}, the body's contacts {:.1} ({:.0} %), its wrench {:.2})",
            m.steps,
            m.wall_s,
            play,
            play / m.wall_s.max(1e-12),
            m.ms_per_step,
            c.assemble,
            c.solve,
            c.collide,
            100.0 * c.collide / m.ms_per_step.max(1e-12),
            m.body_wrench_ms_per_step
        ));
    }
    out.push(format!(
        "weight {:.3} N, force on the body {:.3} N over {:.1} cm² (mean pressure {:.1} Pa, peak {:.1} Pa); largest seam gap {:.2} mm; {} vertices inside the body",
        fit.weight_n,
        fit.contact_force_magnitude_n,
        1e4 * fit.contact_area_m2,
        fit.mean_pressure_pa,
        fit.peak_pressure_pa,
        fit.largest_seam_gap_mm,
        fit.body_penetrations
    ));
    if let Some(bw) = &fit.body_wrench {
        let (f, m) = (bw.mean_force_n, bw.mean_torque_nm);
        // the sewing's first steps slam the panels onto the body: its peak
        // is named apart from the garment's as sewn
        let after = bw
            .peak_force_after_sewing_n
            .zip(bw.peak_force_after_sewing_time_s);
        // the run's peak is a sewing step's unless it is the one after sewing
        let sewing = match after {
            Some((_, t)) if t == bw.peak_force_time_s => String::new(),
            _ => format!(
                " (while sewing {:.3} N at t = {:.2} s)",
                bw.peak_force_n, bw.peak_force_time_s
            ),
        };
        let after = match after {
            Some((f, t)) => format!("peak force after sewing {f:.3} N at t = {t:.2} s"),
            None => "no step after sewing".to_string(),
        };
        out.push(format!(
            "on the body (mean of the last {} s): force ({:.3}, {:.3}, {:.3}) N ({:.3} of the \
             weight downward), torque ({:.4}, {:.4}, {:.4}) N m; {after}{sewing}",
            WRENCH_MEAN_S, f[0], f[1], f[2], bw.mean_down_over_weight, m[0], m[1], m[2],
        ));
    }
    if let Some(bp) = &fit.body_pressure {
        out.push(format!(
            "pressure on the body: {} vertices over {:.1} cm², peak {:.1} Pa, Σ pressure × area \
             {:.4} N (normal force {:.4} N)",
            bp.loaded_vertices,
            1e4 * bp.loaded_area_m2,
            bp.peak_pressure_pa,
            bp.pressure_integral_n,
            bp.normal_force_n
        ));
    }
    for (name, gf) in &fit.girths {
        if let Some(e) = gf.ease_cm {
            out.push(format!(
                "  {name} (z = {:.2} m): body {:.1} cm, garment {:.1} cm, ease {e:.1} cm",
                gf.height_m,
                gf.body_cm.unwrap_or(0.0),
                gf.garment_cm.unwrap_or(0.0)
            ));
        }
    }
    out
}

fn dressing_summary(t: &Trial, fit: &Fit, report: &DressingReport) -> Vec<String> {
    let mut out = Vec::new();
    let r = report;
    out.push(format!(
        "{}: {} arm, wrist to shoulder {:.3} m{}; {} of {} vertices, {} held by the gripper; \
         {} dressing steps in {:.1} s wall ({:.1} ms/step)",
        t.garment.name,
        match r.arm {
            Side::Left => "left",
            Side::Right => "right",
        },
        r.arm_length_m,
        match r.hand {
            Hand::Mesh => "",
            Hand::Hull => ", the hand as its convex hull",
        },
        match r.grip {
            Grip::Cuff => "cuff",
            Grip::Armhole => "armhole",
        },
        r.cuff_vertices,
        r.gripped_vertices,
        r.steps,
        fit.run.wall_s,
        r.ms_per_step
    ));
    out.push(format!(
        "progress {:.3} m ({:.1} % of wrist to shoulder), held opening's centroid {:.1} cm from \
         the shoulder point (the gripper's ring tilted {:.0}° there), the sleeve's cuff {:.3} m \
         from the wrist; peak force on the arm \
         {:.3} N at t = {:.2} s (on the hand {:.3} N; past the wrist {:.3} N at t = {:.2} s, \
         {:.1} cm from the wrist), on the body {:.3} N, on the gripper {:.3} N; {} vertices \
         inside the body",
        r.final_progress_m,
        100.0 * r.final_progress,
        100.0 * r.final_distance_to_shoulder_m,
        r.path_end_tilt_deg,
        r.final_sleeve_end_progress_m,
        r.peak_arm_force_n,
        r.peak_arm_force_time_s,
        r.peak_hand_force_n,
        r.peak_wrist_to_shoulder_force_n,
        r.peak_wrist_to_shoulder_force_time_s,
        100.0 * r.peak_wrist_to_shoulder_force_at_m,
        r.peak_body_force_n,
        r.peak_gripper_force_n,
        fit.body_penetrations
    ));
    if let (Some(f), Some(ts)) = (r.force_limit_n, r.safety_stop_s) {
        out.push(format!(
            "safety stop: the garment pulled on the gripper with more than {f} N at t = {ts:.3} s; \
             the gripper stopped there"
        ));
    }
    out
}
