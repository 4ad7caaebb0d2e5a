"""The process shell around every command: argument checks (`checks`), what precedes MuJoCo's first import
(`startup`), the process runner that turns Ctrl-C and SIGTERM into one line (`process`), JAX's process-wide
settings and compile cache (`jaxsetup`), results written whole or not at all (`files`), and memory sizes
(`budget`). Pure Python below JAX: nothing here builds a model or compiles a step."""
