"""The study: experiments, summaries, reports, figures, animations, metrics, recordings."""
