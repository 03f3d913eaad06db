//! blendtrack core: path tracking with a dynamic control point (placeholder, filled in next commit).
