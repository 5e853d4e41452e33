"""Cart pendulum: MuJoCo plant, the paper's analytic model as MPC predictor, LQR on the error."""
