//! passangle software-in-the-loop simulator (DESIGN.md section 7). Filled by the simulator issues.
