//! Camera control at the protocol level, against fake devices: V4L2's control ioctls
//! (`fake_v4l2`) and a USB3 Vision camera's GenCP control endpoint with its GenICam file
//! (`fake_u3v`). No camera is attached where these run; the fakes answer with the protocols'
//! own structures and bytes, errors included.

mod fake_u3v;
mod fake_v4l2;
mod gencp;
mod genicam;
mod live;
mod v4l2;
