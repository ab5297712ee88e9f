"""What people look at: Rerun recordings, run summaries, the HTML report."""
