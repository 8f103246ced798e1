"""The real-traffic study (issue 34 item 4): peers judged against recorded aircraft."""
