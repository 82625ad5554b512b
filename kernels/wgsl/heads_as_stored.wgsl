// copy_heads.wgsl between tensors of the kernel's storage type.
alias SRC = S;
alias DST = S;
