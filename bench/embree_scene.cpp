// placeholder: the Embree baseline adapter (issue 3) goes here.
