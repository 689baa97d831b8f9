"""Conservative inflation: the planning geometry P~+ = P~ u Q u I."""
