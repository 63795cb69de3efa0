"""Outside input, checked at every level before it is used: `files` (a path that names a
readable regular file of a sane size), `images` (an image file, header to decoded pixels),
`numeric` (the one grammar numbers from outside are read by) and `strict_yaml` (the one strict
reading of YAML files and text)."""
