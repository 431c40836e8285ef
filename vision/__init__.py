"""Camera images to feature points: the image front-ends EvoPose's search is fed with (docs/design.md §1, §5).

* :mod:`vision.features` — the hue-band marks of drawn worlds (the paper's Section IV), chessboard corners,
  matching detections to the truth;
* :mod:`vision.blobs` — the contrast front-end for camera images: spots by scale-normalised contrast, labelled by
  their paint (:mod:`vision.spot_colour`), kept by the selection rules (:mod:`vision.mark_selection`) and the body
  (:mod:`vision.body_paint`), scored (:mod:`vision.mark_scorer`), positioned (:mod:`vision.spot_position`);
* :mod:`vision.camera_look` — a camera's look (white balance, saturation, hue) estimated and undone;
* :mod:`vision.extract` — the front-end an agent or ``evopose solve --image`` uses for a target model;
* :mod:`vision.images` — image files, a search box from one camera, an overlay;
* :mod:`vision.train_scorer` — fitting the mark scorer on rendered datasets.

Nothing here searches poses: :mod:`evopose` never imports this package.
"""
