//! Passing-angle calculator (DESIGN.md section 6 step 8).
