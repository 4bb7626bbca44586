//! Point clouds: the shared point type and PLY/PCD/XYZ input and output.
