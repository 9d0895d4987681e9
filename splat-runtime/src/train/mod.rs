//! What training shares across methods (DESIGN §10), built up step by step: the photometric
//! loss with its gradient and the evaluation metrics ([`loss`]), and Adam ([`adam`]).

pub mod adam;
pub mod loss;
