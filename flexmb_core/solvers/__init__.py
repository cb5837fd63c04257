"""Newton–Raphson building blocks and the sparse linear solve on the fixed pattern."""
