# Where splat objects' settings and tools are shown (panels).
