//! The iceoryx2 service type of every port: iceoryx2's `ipc` service with two differences. Its
//! global management segment (a node counter) is a file in the namespace's private root
//! directory instead of a POSIX shared-memory object in `/dev/shm`, and that file is owner-only:
//! iceoryx2 creates it and then makes it world-writable (0666, "global access"), and any local
//! user could open it in that moment and keep writing to it. [`OwnerOnlyFile`] is iceoryx2's file
//! storage with the global access switched off, so the file goes from write-only for its owner
//! (while being initialised) straight to 0600, and it lives in a 0700 directory besides. And its
//! in-process reference counting recycles its boxes ([`super::recycled`]): iceoryx2 creates one
//! per loaned sample, which would be a heap allocation per publish in the board's 1 kHz loop.
//! Every other resource is iceoryx2's own `ipc` one (owner-only shared memory in `/dev/shm`,
//! service and node files under the root directory), so clients of the plain `ipc` service
//! (iceoryx2's Python bindings) still talk to the same services.
//!
//! [`ThreadSafe`] is the same service with iceoryx2's mutex-protected reference counting instead
//! (ports that may be used from any thread): the bridge publishes from Zenoh's callbacks with it.

use core::fmt::Debug;
use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::time::Duration;
use iceoryx2::prelude::{FileName, Path};
use iceoryx2::service::ipc;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_memory::bump_allocator::BumpAllocator;
use iceoryx2_bb_posix::file::AccessMode;
use iceoryx2_cal::dynamic_storage::{
    DynamicStorage, DynamicStorageBuilder, DynamicStorageCreateError, DynamicStorageOpenError,
    DynamicStorageOpenOrCreateError,
};
use iceoryx2_cal::named_concept::{
    NamedConcept, NamedConceptBuilder, NamedConceptDoesExistError, NamedConceptListError,
    NamedConceptMgmt, NamedConceptPathHintRemoveError, NamedConceptRemoveError,
};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator as ShmBumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// Both service types: iceoryx2's `ipc` resources with the owner-only global file; `$policy` is
/// the in-process reference counting of the ports' shared state (the only difference).
macro_rules! vic_service {
    ($(#[$doc:meta])* $name:ident, $policy:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone)]
        pub struct $name {}

        impl iceoryx2::service::Service for $name {
            type StaticStorage = <ipc::Service as iceoryx2::service::Service>::StaticStorage;
            type ConfigSerializer =
                <ipc::Service as iceoryx2::service::Service>::ConfigSerializer;
            /// The one change of resource: an owner-only file under `global.root_path` (the
            /// private directory).
            type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
                OwnerOnlyFile<T>;
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
            type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = $policy<T>;
            type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
                dynamic_storage::recommended::Ipc<KeyType>;
            type BlackboardPayload = shared_memory::recommended::Ipc<ShmBumpAllocator>;
            type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
        }

        impl iceoryx2::service::internal::ServiceInternal<$name> for $name {}
    };
}

use super::recycled::Recycled;
use iceoryx2_cal::arc_sync_policy::mutex_protected::MutexProtected;

vic_service!(
    /// iceoryx2's `ipc` service with its global management segment an owner-only file in the
    /// private root directory, and iceoryx2's single-threaded reference counting with its boxes
    /// recycled, so a publish takes no memory from the allocator (`super::recycled`). Its ports
    /// are neither `Send` nor `Sync`. Every daemon's service type.
    Service,
    Recycled
);

vic_service!(
    /// [`Service`]'s thread-safe sibling: the same resources (so its ports and [`Service`]'s
    /// talk to each other on one service, and the namespace's files and their modes are the
    /// same), with iceoryx2's `MutexProtected` policy (as `ipc_threadsafe`): its ports are `Send`
    /// and `Sync`, at the cost of a mutex per port operation and an allocation per loan. For
    /// the bridge's publishers, which run on Zenoh's threads; never in the board's 1 kHz loop.
    ThreadSafe,
    MutexProtected
);

type File<T> = dynamic_storage::file::Storage<T>;
type FileBuilder<'b, T> = dynamic_storage::file::Builder<'b, T>;

/// iceoryx2's file-backed dynamic storage that never grants global access: its files end 0600
/// whatever the caller asks for. Everything else is delegated unchanged.
#[derive(Debug)]
pub struct OwnerOnlyFile<T: Debug + Send + Sync + ZeroCopySend>(File<T>);

/// The builder of [`OwnerOnlyFile`]: iceoryx2's file builder with `enable_global_access` ignored.
#[derive(Debug)]
pub struct OwnerOnlyBuilder<'b, T: Debug + Send + Sync + ZeroCopySend>(FileBuilder<'b, T>);

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConcept for OwnerOnlyFile<T> {
    fn name(&self) -> &FileName {
        self.0.name()
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptMgmt for OwnerOnlyFile<T> {
    type Configuration = <File<T> as NamedConceptMgmt>::Configuration;

    unsafe fn remove_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptRemoveError> {
        // SAFETY: the caller's contract is the one of the storage delegated to.
        unsafe { File::<T>::remove_cfg(name, cfg) }
    }
    fn does_exist_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptDoesExistError> {
        File::<T>::does_exist_cfg(name, cfg)
    }
    fn list_cfg(cfg: &Self::Configuration) -> Result<Vec<FileName>, NamedConceptListError> {
        File::<T>::list_cfg(cfg)
    }
    fn remove_path_hint(value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        File::<T>::remove_path_hint(value)
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> Abandonable for OwnerOnlyFile<T> {
    unsafe fn abandon_in_place(mut this: NonNull<Self>) {
        // SAFETY: the caller's contract, passed on to the one field.
        unsafe { File::<T>::abandon_in_place(NonNull::from_mut(&mut this.as_mut().0)) };
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> DynamicStorage<T> for OwnerOnlyFile<T> {
    type Builder<'b> = OwnerOnlyBuilder<'b, T>;

    fn does_support_persistency() -> bool {
        File::<T>::does_support_persistency()
    }
    fn has_ownership(&self) -> bool {
        self.0.has_ownership()
    }
    fn release_ownership(&self) {
        self.0.release_ownership()
    }
    fn acquire_ownership(&self) {
        self.0.acquire_ownership()
    }
    fn get(&self) -> &T {
        self.0.get()
    }
    fn default_suffix() -> FileName {
        File::<T>::default_suffix()
    }
    unsafe fn __internal_set_type_name_in_config(config: &mut Self::Configuration, name: &str) {
        // SAFETY: delegated unchanged.
        unsafe { File::<T>::__internal_set_type_name_in_config(config, name) }
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptBuilder<OwnerOnlyFile<T>>
    for OwnerOnlyBuilder<'_, T>
{
    fn new(name: &FileName) -> Self {
        OwnerOnlyBuilder(FileBuilder::<T>::new(name).enable_global_access(false))
    }
    fn config(self, config: &<OwnerOnlyFile<T> as NamedConceptMgmt>::Configuration) -> Self {
        OwnerOnlyBuilder(self.0.config(config))
    }
}

impl<'b, T: Debug + Send + Sync + ZeroCopySend> DynamicStorageBuilder<'b, T, OwnerOnlyFile<T>>
    for OwnerOnlyBuilder<'b, T>
{
    fn has_ownership(self, value: bool) -> Self {
        OwnerOnlyBuilder(self.0.has_ownership(value))
    }
    /// Ignored: the file stays owner-only (the reason this type exists).
    fn enable_global_access(self, _value: bool) -> Self {
        self
    }
    fn supplementary_size(self, value: usize) -> Self {
        OwnerOnlyBuilder(self.0.supplementary_size(value))
    }
    fn timeout(self, value: Duration) -> Self {
        OwnerOnlyBuilder(self.0.timeout(value))
    }
    fn initializer<F: FnMut(&mut MaybeUninit<T>, &mut BumpAllocator) -> bool + 'b>(
        self,
        value: F,
    ) -> Self {
        OwnerOnlyBuilder(self.0.initializer(value))
    }
    fn create(self) -> Result<OwnerOnlyFile<T>, DynamicStorageCreateError> {
        self.0.create().map(OwnerOnlyFile)
    }
    fn open(self, access_mode: AccessMode) -> Result<OwnerOnlyFile<T>, DynamicStorageOpenError> {
        self.0.open(access_mode).map(OwnerOnlyFile)
    }
    fn open_or_create(self) -> Result<OwnerOnlyFile<T>, DynamicStorageOpenOrCreateError> {
        self.0.open_or_create().map(OwnerOnlyFile)
    }
}
