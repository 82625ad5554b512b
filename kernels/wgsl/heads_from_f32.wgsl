// copy_heads.wgsl from f32 into the kernel's storage type (f16).
alias SRC = f32;
alias DST = S;
