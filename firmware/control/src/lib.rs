//! passangle firmware logic (DESIGN.md section 5): kinematics, wheel PID, odometry, safety.
//! `no_std`, no alloc, no clocks: time comes in, currents and reports go out. Filled by the firmware issue.
#![cfg_attr(not(test), no_std)]
