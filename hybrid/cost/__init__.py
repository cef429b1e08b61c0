"""The per-tile cost model: features known before drawing, the linear model and its fit, and the frame planner."""
