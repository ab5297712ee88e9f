"""The papers' own experiments: 000's SINS experiments and 002's turntable."""
