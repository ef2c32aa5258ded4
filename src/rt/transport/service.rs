//! The iceoryx2 service type of every port: iceoryx2's `ipc` service with one difference. Its
//! global management segment (a node counter) is a file in the namespace's private root
//! directory instead of a POSIX shared-memory object in `/dev/shm`: iceoryx2 creates that object
//! and then makes it world-writable (0666), and any local user could open it in that moment and
//! keep writing to it. In a 0700 directory no other user can reach the file whatever its mode.
//! Every other resource is iceoryx2's own `ipc` one (owner-only shared memory in `/dev/shm`,
//! service and node files under the root directory), so clients of the plain `ipc` service
//! (iceoryx2's Python bindings) still talk to the same services.

use core::fmt::Debug;
use iceoryx2::service::ipc;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// iceoryx2's `ipc` service with its global management segment in the private root directory.
#[derive(Debug, Clone)]
pub struct Service {}

impl iceoryx2::service::Service for Service {
    type StaticStorage = <ipc::Service as iceoryx2::service::Service>::StaticStorage;
    type ConfigSerializer = <ipc::Service as iceoryx2::service::Service>::ConfigSerializer;
    /// The one change: a file under `global.root_path` (the private directory).
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::file::Storage<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = event::recommended::Ipc;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Service> for Service {}
