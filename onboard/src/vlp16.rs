//! VLP-16 decoding, frame assembly and sources (DESIGN.md section 6 step 1).
