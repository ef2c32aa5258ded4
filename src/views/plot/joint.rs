//! Fig. 2: the single joint (angle and velocity trials, commands).

use super::*;

pub(super) const JOINT_ANGLE_HEIGHT: u32 = 280;
pub(super) const JOINT_TIME_HEIGHT: u32 = 235;

pub(super) struct JointFigure<'a> {
    pub(super) axes: ColumnAxes<'a>,
}

impl<'a> JointFigure<'a> {
    pub(super) fn new(columns: &'a [ColumnPlot]) -> Self {
        let trial_values = |data: fn(&ColumnPlot) -> &Vec<Vec<Vec<f64>>>| -> Vec<Vec<f64>> {
            columns
                .iter()
                .map(|c| {
                    c.kept(data(c))
                        .flatten()
                        .flat_map(|knot| knot.iter().take(c.dof).map(|v| v * RAD_TO_DEG))
                        .collect()
                })
                .collect()
        };
        let angle = shared_range(trial_values(|c| &c.q), &reference_degrees(columns), false);
        let velocity = shared_range(trial_values(|c| &c.qd), &[], false);
        JointFigure {
            axes: ColumnAxes::new(columns, angle, velocity),
        }
    }

    /// Every trial of every joint's angle [deg] (with the reference) or velocity [deg/s].
    pub(super) fn draw_trials<'c, DB: DrawingBackend + 'c>(
        &self,
        chart: &mut Chart<'c, DB>,
        c: usize,
        angles: bool,
    ) -> DrawResult<(), DB> {
        let col = &self.axes.columns[c];
        let view = View::of(chart);
        let data = if angles { &col.q } else { &col.qd };
        let mut drawn = Vec::new();
        for j in 0..col.dof {
            let colour = joint_colour(j);
            for (t, trial) in data.iter().enumerate() {
                let points = joint_degrees(&col.time, trial, j);
                if col.is_diverged(t) {
                    dashed(
                        chart,
                        &view,
                        &points,
                        colour.mix(DIVERGED_ALPHA).stroke_width(1),
                    )?;
                    continue;
                }
                lines(
                    chart,
                    &view,
                    points.iter().copied(),
                    colour.mix(0.45).stroke_width(1),
                )?;
                drawn.extend(points);
            }
            if angles {
                let reference = joint_degrees(&col.time, &col.reference_q, j);
                dashed(chart, &view, &reference, BLACK.stroke_width(2))?;
            }
        }
        // The legend once, on the first column's angles.
        if c == 0 && angles {
            if col.dof > 1 {
                for j in 0..col.dof {
                    legend_line(
                        chart,
                        &format!("joint {}", j + 1),
                        joint_colour(j).stroke_width(2),
                    )?;
                }
            } else {
                legend_line(chart, "trials", joint_colour(0).mix(0.6).stroke_width(1))?;
            }
            if !col.reference_q.is_empty() {
                legend_dashed(chart, "reference", BLACK.stroke_width(2))?;
            }
            if self.axes.columns.iter().any(|c| c.n_diverged() > 0) {
                legend_dashed(
                    chart,
                    "diverged trial",
                    joint_colour(0).mix(DIVERGED_ALPHA).stroke_width(1),
                )?;
            }
            legend(chart, quiet_corner(&view, &drawn))?;
        }
        Ok(())
    }
}

impl ColumnFigure for JointFigure<'_> {
    const LETTER_PANELS: [usize; 3] = [0, 1, 2];

    fn axes(&self) -> &ColumnAxes<'_> {
        &self.axes
    }

    fn own_heights(&self) -> (Vec<u32>, u32) {
        (
            vec![JOINT_ANGLE_HEIGHT, JOINT_TIME_HEIGHT],
            JOINT_TIME_HEIGHT,
        )
    }

    fn draw_own<DB: DrawingBackend>(
        &self,
        c: usize,
        panels: &[DrawingArea<DB, Shift>],
    ) -> DrawResult<(), DB> {
        let a = &self.axes;
        let top = column_titled(&panels[0], a.columns, c, false)?;
        let mut chart = time_chart(&top, a.time, a.angle, "angle [deg]", false)?;
        self.draw_trials(&mut chart, c, true)?;
        let mut chart = time_chart(&panels[1], a.time, a.velocity, "velocity [deg/s]", false)?;
        self.draw_trials(&mut chart, c, false)
    }
}
