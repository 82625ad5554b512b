// copy_heads.wgsl from the kernel's storage type (f16) into f32.
alias SRC = S;
alias DST = f32;
