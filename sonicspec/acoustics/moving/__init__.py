"""Moving sources and microphones: each exact path rendered as a time-varying delay, the
emission time of every output sample solved from the retarded-time equation
(:mod:`.delays`, its compiled loops in :mod:`._delay_kernels`)."""
