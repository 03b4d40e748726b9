"""astro-reason's regional_coverage benchmark as data: cases, solutions, strip geometry, battery, the checker."""
